"""Eq. 2 is right whichever packet the triggers fire from (issue 9, item 1).

Drivers trigger from the packet containing the zero crossing, the first packet whose
first block is past it (drivers cutting revolutions by packet), or a fixed number of
packets after or before it. The simulator writes each with exact truth; the audit must
recover the ideal delay, and per frame t_rotate and the packet phase, under all of them,
for every simulated LiDAR model, with synchronised and with offset sensor clocks.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, get_args

import numpy as np
import pytest

from syncaudit.audit.run import AuditResult, audit_log
from syncaudit.cli.simulate_controller import ControllerDelays
from syncaudit.simulate import LidarModel
from syncaudit.simulate.rig_file import rig_from_truth
from syncaudit.simulate.sync_log import CameraSim, SyncSimConfig, simulate_sync_log

MODELS: tuple[LidarModel, ...] = get_args(LidarModel)
CONVENTIONS = [("containing", 0), ("first_after", 0), ("containing", 3), ("containing", -3)]
TOLERANCE_NS = 20_000
PER_FRAME_NS = 5_000
"""Per-frame t_rotate / phase: the packets' 0.01 deg azimuths limit them to ~2.5 us."""
CAMERAS = [CameraSim(name="front", yaw_deg=0.0), CameraSim(name="left", yaw_deg=100.0)]


def _run(
    tmp_path: Path, delays: ControllerDelays | None = None, **config: Any
) -> tuple[AuditResult, dict[str, Any]]:
    out = tmp_path / "log.mcap"
    config.setdefault("cameras", CAMERAS)
    config.setdefault("duration_s", 0.6)
    truth = simulate_sync_log(out, SyncSimConfig(**config), delays=delays)
    return audit_log(out, rig_from_truth(truth), jobs=1), truth


def _truth_of(truth_cam: dict[str, Any], seqs: np.ndarray, key: str) -> np.ndarray:
    by_seq = {f["frame_sequence"]: f[key] for f in truth_cam["frames"]}
    return np.array([by_seq[int(s)] for s in seqs], dtype=np.float64)


def _check(result: AuditResult, truth: dict[str, Any]) -> None:
    assert len(result.cameras) == len(CAMERAS)
    for cam in result.cameras:
        sync, t = cam.sync, truth["cameras"][cam.sync.camera]
        frames = sync.frames
        assert sync.frames_paired == sync.frames_total == len(t["frames"])
        assert sync.packet_phase_source == "trigger packet"
        assert sync.delay_recommended_ns == pytest.approx(
            t["ideal_delay_mean_ns"], abs=TOLERANCE_NS
        )
        assert sync.packet_phase_ns == pytest.approx(t["packet_phase_mean_ns"], abs=PER_FRAME_NS)
        seqs = frames["frame_sequence"].to_numpy()
        for column in ("t_rotate_ns", "packet_phase_ns", "error_signed_ns"):
            truth_key = "error_ns" if column == "error_signed_ns" else column
            got = frames[column].to_numpy(np.float64)
            assert np.max(np.abs(got - _truth_of(t, seqs, truth_key))) < PER_FRAME_NS, column
        # Self-consistency: the recommended delay applied to the log's own timings.
        t_l = frames["t_l_ns"].to_numpy(np.int64)
        t_est = frames["t_estimated_ns"].to_numpy(np.int64)
        applied = frames["applied_delay_ns"].to_numpy(np.float64)
        corrected = (t_l - t_est) - applied + sync.delay_recommended_ns
        assert abs(float(corrected.mean())) < TOLERANCE_NS


@pytest.mark.parametrize(("convention", "offset"), CONVENTIONS)
@pytest.mark.parametrize("model", MODELS)
def test_recommended_delay_under_every_trigger_packet_convention(
    tmp_path: Path, model: LidarModel, convention: str, offset: int
) -> None:
    result, truth = _run(
        tmp_path,
        seed=7,
        lidar_model=model,
        trigger_packet=convention,
        trigger_packet_offset=offset,
        cameras=[c.model_copy(update={"delay_error_us": 900.0}) for c in CAMERAS],
    )
    _check(result, truth)


@pytest.mark.parametrize(
    ("model", "convention", "offset", "clock_offset_ns"),
    [
        ("VLP-32C", "first_after", 0, 1_234_567_890),
        ("VLS-128", "containing", 3, -2_500_000_000),
        ("Pandar40P", "containing", -3, 2_500_000_000),
        ("PandarXT32", "first_after", 2, -1_234_567_890),
    ],
)
def test_conventions_with_an_unsynchronised_sensor_clock(
    tmp_path: Path, model: LidarModel, convention: str, offset: int, clock_offset_ns: int
) -> None:
    """The host offset is found from the triggers' t1 and the packet grid, not by assuming
    the trigger names the zero packet (which would move every crossing by packets)."""
    result, truth = _run(
        tmp_path,
        seed=8,
        lidar_model=model,
        trigger_packet=convention,
        trigger_packet_offset=offset,
        clock_offset_ns=clock_offset_ns,
    )
    assert result.lidar.clock_synchronised is False
    assert result.clock_offset_ns == pytest.approx(-clock_offset_ns, abs=2_000)
    _check(result, truth)


def test_first_after_names_a_later_packet_in_most_revolutions(tmp_path: Path) -> None:
    """The convention differs from 'containing' where it should, and the truth says so."""
    base = SyncSimConfig(duration_s=1.0, cameras=CAMERAS, seed=7, lidar_model="VLP-32C")
    phases = {}
    for convention in ("containing", "first_after"):
        cfg = base.model_copy(update={"trigger_packet": convention})
        truth = simulate_sync_log(tmp_path / f"{convention}.mcap", cfg)
        phases[convention] = np.array(
            [f["packet_phase_ns"] for f in truth["cameras"]["front"]["frames"]]
        )
        assert truth["conventions"]["trigger_packet"].startswith(convention)
    later = phases["first_after"] < phases["containing"]
    assert later.mean() > 0.5
    # Where they differ, the first-after packet is one packet period later.
    period = truth["lidar"]["packet_period_ns"]
    step = (phases["containing"] - phases["first_after"])[later]
    assert np.all(np.abs(step - period) < 2_000)


def test_offset_outside_the_log_is_refused(tmp_path: Path) -> None:
    cfg = SyncSimConfig(duration_s=0.35, cameras=CAMERAS, start_azimuth_deg=0.0)
    cfg = cfg.model_copy(update={"zero_azimuth_deg": 0.5, "trigger_packet_offset": -32})
    with pytest.raises(ValueError, match="trigger_packet_offset"):
        simulate_sync_log(tmp_path / "log.mcap", cfg)


def test_self_consistency_with_the_controller_changing_the_delay(tmp_path: Path) -> None:
    """Applied delays that change frame by frame (the live controller) change nothing."""
    from syncaudit.analysis.controller import ControllerConfig

    result, truth = _run(
        tmp_path,
        seed=12,
        duration_s=2.0,
        lidar_model="VLP-32C",
        trigger_packet="first_after",
        delays=ControllerDelays(ControllerConfig(window_frames=5, min_frames=5)),
        cameras=[c.model_copy(update={"delay_error_us": 1500.0}) for c in CAMERAS],
    )
    for cam in result.cameras:
        applied = truth["cameras"][cam.sync.camera]["applied_delay"]
        assert applied["adjustments"], "the controller should have moved the delay"
    _check(result, truth)
