"""Scans taken while moving in the calibration (`calib.alignment.moving_scans`), on a
simulated drive with short stops and wide turns: most of its scans are moving ones."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from syncaudit.calib import CalibConfig, calibrate_log, se3
from syncaudit.calib.result import CalibrationResult
from syncaudit.calib.settings import MovingScansConfig
from syncaudit.simulate.calib_config import calib_scene_config
from syncaudit.simulate.calib_session import simulate_calib_session


@pytest.fixture(scope="module")
def short_stops(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """A 16-beam left/right drive: 5 stops of 0.2-0.3 s (2-3 still sweeps), 70-85 deg
    turns between them (10-18 moving sweeps each): 114 of its 140 scans are moving."""
    out = tmp_path_factory.mktemp("moving") / "short.mcap"
    config = calib_scene_config(beams=16, motion="drive", n_stops=5, mount="roof_left_right")
    config = config.model_copy(
        update={"turn_deg_range": (70.0, 85.0), "stop_duration_s_range": (0.2, 0.3)}
    )
    return out, simulate_calib_session(out, config)


def _error(result: CalibrationResult, truth: dict[str, Any]) -> tuple[float, float]:
    ext = result.extrinsics[0]
    assert ext.result is not None, result.reason
    true = np.array(truth["lidars"][1][f"true_{truth['reference_lidar']}_from_lidar"]["matrix"])
    rot_deg, trans_m = se3.transform_difference(true, np.array(ext.result.matrix))
    return rot_deg, trans_m * 100.0


def test_moving_scans_are_deskewed_used_and_counted(
    short_stops: tuple[Path, dict[str, Any]],
) -> None:
    """With the moving scans: every LiDAR's moving scans are accounted for (used or
    rejected with a reason), some join the joint graph as 'moving' links, and the
    calibration stays within the 16-beam target against the truth (measured: 0.060 deg
    / 0.36 cm; without them 0.062 / 0.36, `benchmarks/bench_moving_scans.py`)."""
    path, truth = short_stops
    result = calibrate_log(path, CalibConfig(moving_scans=MovingScansConfig(use="always")))
    moving_truth = {
        lidar["topic"]: sum(
            1 for s in truth["scans"] if s["topic"] == lidar["topic"] and not s["static"]
        )
        for lidar in truth["lidars"]
    }
    for lidar in result.lidars:
        report = lidar.moving_scans
        assert report is not None
        # The stop detection keeps a few slow sweeps next to each stop as still ones.
        assert 0.8 * moving_truth[lidar.topic] <= report.seen <= moving_truth[lidar.topic]
        assert report.used > 0 and report.deskewed >= report.used
        assert report.used + sum(report.rejected.values()) == report.seen
        assert report.motion_source is not None and "refined" in report.motion_source
        assert any(n.startswith(f"{lidar.topic}: {report.used} of") for n in result.notes)
    used = sum(lidar.moving_scans.used for lidar in result.lidars if lidar.moving_scans)
    assert result.joint is not None and result.joint.links["moving"] >= used
    rot_deg, trans_cm = _error(result, truth)
    assert rot_deg < 0.3 and trans_cm < 2.0
