"""The sync audit against simulated logs with known truth (issue: method end to end).

Real recordings carry no camera side, so the camera half of the method is checked on
logs whose ground truth the simulator states exactly (see simulate/sync_log.py).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from syncaudit.analysis.stats import error_mean, error_variance
from syncaudit.audit.run import AuditResult, audit_log
from syncaudit.simulate.rig_file import rig_from_truth
from syncaudit.simulate.sync_log import LightModel, SyncSimConfig, simulate_sync_log

STEADY_LIGHT = LightModel(dark_exposure_us=2_000.0)


def _simulate(tmp_path: Path, name: str, **overrides: Any) -> tuple[Path, dict[str, Any]]:
    out = tmp_path / name
    config = SyncSimConfig(duration_s=overrides.pop("duration_s", 4.0), **overrides)
    truth = simulate_sync_log(out, config)
    return out, truth


def _audit(out: Path, truth: dict[str, Any]) -> AuditResult:
    return audit_log(out, rig_from_truth(truth))


def _frame_truth(truth_cam: dict[str, Any], seqs: np.ndarray, key: str) -> np.ndarray:
    by_seq = {f["frame_sequence"]: f for f in truth_cam["frames"]}
    return np.array([by_seq[int(s)][key] for s in seqs], dtype=np.float64)


CASES = [
    ("VLP-16", 11, 0),
    ("VLP-32C", 12, 0),
    ("Pandar40P", 13, 0),
    ("PandarXT32", 14, 0),
    ("VLP-16", 15, 1_234_567_890),  # sensor clock 1.23 s ahead of the host
    ("Pandar40P", 16, -2_500_000_000),
]


@pytest.mark.parametrize(("model", "seed", "clock_offset_ns"), CASES)
def test_audit_recovers_the_truth(
    tmp_path: Path, model: str, seed: int, clock_offset_ns: int
) -> None:
    out, truth = _simulate(
        tmp_path, "log.mcap", lidar_model=model, seed=seed, clock_offset_ns=clock_offset_ns
    )
    result = _audit(out, truth)
    assert len(result.cameras) == len(truth["cameras"])
    for cam in result.cameras:
        sync, t = cam.sync, truth["cameras"][cam.sync.camera]
        assert sync.frames_paired == sync.frames_total == len(t["frames"])
        for name in ("t1", "t2", "t3", "t4"):
            assert sync.latencies[name].status == "observed"
            assert sync.latencies[name].mean_ns == pytest.approx(t[f"{name}_mean_ns"], abs=2_000)
        assert sync.t_rotate_ns == pytest.approx(t["t_rotate_ns"], abs=10_000)
        frames = sync.frames
        seqs = frames["frame_sequence"].to_numpy()
        true_error = _frame_truth(t, seqs, "error_ns")
        assert np.max(np.abs(frames["error_signed_ns"].to_numpy() - true_error)) < 20_000
        true_estimated = _frame_truth(t, seqs, "t_estimated_ns")
        assert np.max(np.abs(frames["t_estimated_ns"].to_numpy() - true_estimated)) < 20_000
        # Eq. 5 and Eq. 6 as the truth computes them directly.
        assert sync.error_mean_ns == pytest.approx(t["error_mean_ns"], abs=20_000)
        assert sync.error_var_ns2 == pytest.approx(t["error_var_ns2"], rel=0.05, abs=4e8)
        assert error_mean(np.abs(true_error)) == pytest.approx(t["error_mean_ns"], abs=1e-6)
        assert error_variance(np.abs(true_error)) == pytest.approx(t["error_var_ns2"], rel=1e-9)
        assert sync.delay_recommended_ns == pytest.approx(t["ideal_delay_mean_ns"], abs=20_000)
        assert sync.delay_from_error_ns == pytest.approx(t["ideal_delay_mean_ns"], abs=20_000)


def test_offset_clock_is_reported_and_removed(tmp_path: Path) -> None:
    out, truth = _simulate(tmp_path, "log.mcap", seed=21, clock_offset_ns=1_531_000_000_000 // 1000)
    result = _audit(out, truth)
    assert result.lidar.clock_synchronised is False
    assert result.clock_offset_ns == pytest.approx(-truth["lidar"]["clock_offset_ns"], abs=2e6)
    assert any("not synchronised" in w for w in result.warnings)


@pytest.mark.parametrize("model", ["Pandar40P", "PandarXT32"])
def test_replayed_controller_brings_error_under_thresholds(tmp_path: Path, model: str) -> None:
    out, truth = _simulate(
        tmp_path,
        "log.mcap",
        lidar_model=model,
        seed=31,
        duration_s=6.0,
        light=STEADY_LIGHT,
        cameras=[c.model_copy(update={"delay_error_us": 1800.0}) for c in SyncSimConfig().cameras],
    )
    result = _audit(out, truth)
    thresholds = result.rig.thresholds
    for cam in result.cameras:
        assert cam.sync.needs_correction
        assert cam.sync.error_signed_mean_ns == pytest.approx(1.8e6, abs=1e5)
        replay = cam.replay
        assert replay is not None and replay.adjustments >= 1
        assert replay.settled_error_mean_ns < thresholds.error_mean_us * 1e3
        assert replay.settled_error_var_ns2 < thresholds.error_var_us2 * 1e6


def test_same_log_in_three_containers_gives_identical_results(tmp_path: Path) -> None:
    results = []
    for name in ("log.mcap", "log.db3", "log.bag"):
        fmt = {"mcap": "mcap", "db3": "db3", "bag": "bag"}[name.split(".")[1]]
        out, truth = _simulate(tmp_path, name, seed=41, duration_s=2.0, log_format=fmt)
        data = _audit(out, truth).to_dict()
        for key in ("path", "container"):
            data.pop(key)
        results.append(json.dumps(data, sort_keys=True))
    assert results[0] == results[1] == results[2]


def test_missing_exposure_metadata_counts_unpaired_frames(tmp_path: Path) -> None:
    out, truth = _simulate(tmp_path, "log.mcap", seed=51, duration_s=2.0, exposure_messages=())
    rig = rig_from_truth(truth)
    result = audit_log(out, rig)
    for cam in result.cameras:
        assert cam.sync.frames_paired == 0
        assert cam.sync.unpaired["no exposure metadata"] == cam.sync.frames_total > 0
        assert any("no exposure metadata" in m for m in result.missing)
