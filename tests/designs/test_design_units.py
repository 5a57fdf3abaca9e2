"""The design helpers on hand-written numbers: rig keys, row timing, phase units."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from syncaudit.analysis.designs import DesignGuess, design_setting, guess_design, lock_setting
from syncaudit.analysis.rolling_shutter import row_timing
from syncaudit.rig import CameraConfig


def test_row_time_and_rows_give_the_readout_and_centre_row() -> None:
    timing = row_timing(CameraConfig(name="c", row_time_us=20.0, rows=2160))
    assert timing is not None
    assert timing.readout_ns == pytest.approx(43_200_000.0)
    assert timing.target_row == 1080
    stated = row_timing(CameraConfig(name="c", readout_us=30_000.0, rows=1000, lidar_row=250))
    assert stated is not None and stated.row_time_ns == pytest.approx(30_000.0)
    assert stated.target_row == 250
    assert row_timing(CameraConfig(name="c")) is None


def test_a_rig_with_row_time_but_no_rows_is_one_line_exit_6(tmp_path: Path) -> None:
    rig = tmp_path / "rig.yaml"
    rig.write_text("lidar: {topic: /x}\ncameras:\n  - {name: c, row_time_us: 20}\n")
    log = tmp_path / "x.mcap"
    log.write_bytes(b"")
    run = subprocess.run(
        [sys.executable, "-m", "syncaudit", "audit", str(log), "--rig", str(rig)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert run.returncode == 6, run.stderr
    assert "row_time_us needs rows" in run.stderr
    assert "Traceback" not in run.stderr and len(run.stderr.strip().splitlines()) == 1


def test_sensor_trigger_phase_is_degrees_of_the_interval_in_tenths() -> None:
    # sensor_trigger: start = interval * int64(phase * 10) / 3600, so at 10 Hz 1 deg is
    # 277.8 us; moving a 36.0 deg phase 500 us later is 37.8 deg.
    guess = DesignGuess("ptp_phase", "", 100_000_000.0, 36.0)
    setting = design_setting(guess, 500_000.0, omega_deg_s=3600.0, sync_output_angle_deg=None)
    assert setting is not None
    assert setting["exact_value"] == pytest.approx(37.8)
    assert setting["value"] == pytest.approx(37.8)
    odd = design_setting(guess, 10_000.0, omega_deg_s=3600.0, sync_output_angle_deg=None)
    assert odd is not None and odd["value"] == pytest.approx(36.0)  # 0.036 deg rounds away
    assert odd["quantisation_us"] == pytest.approx(-10.0)


def test_lock_angles_in_the_vendors_units() -> None:
    ouster = lock_setting("ouster", 90.0, 1_000_000.0, 3600.0)
    assert ouster == {
        "parameter": "phase_lock_offset",
        "value": 86400.0,
        "unit": "millideg",
        "current_value": 90000.0,
    }
    hesai = lock_setting("hesai", 1.0, 1_000_000.0, 3600.0)
    assert hesai["parameter"] == "sync_angle" and hesai["value"] == pytest.approx(357.4)


def test_bare_times_on_a_grid_of_pts_time_are_a_phase_trigger() -> None:
    period = 100_000_000
    times = np.arange(50, dtype=np.int64) * period + 1_700_000_000_000_000_000 + 12_345_000
    zero = times - 3_000_000 + np.cumsum(np.full(50, 40_000, dtype=np.int64))  # LiDAR slips
    guess = guess_design(trigger_ns=times, has_checkpoints=False, frame_ns=times, zero_host_ns=zero)
    assert guess.design == "ptp_phase"
    assert guess.phase_deg == pytest.approx(12_345_000 / period * 360.0, abs=1e-6)
    synced = guess_design(
        trigger_ns=zero + 3_000_000, has_checkpoints=False, frame_ns=times, zero_host_ns=zero
    )
    assert synced.design == "lidar_sync_output"
    assert synced.lidar_lag_ns == pytest.approx(3_000_000.0)
