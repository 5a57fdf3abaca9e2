"""Calibration checks of `gate` on real logs of `syncaudit simulate calib` (truth beside them).

A calibration session (two LiDARs' PointCloud2 scans, /tf_static, no LiDAR packets; one
written as a ROS 1 bag, one as MCAP) is judged on its calibration checks: a recorded extrinsic off by more than the policy's
tolerance fails, a correct one passes. A log with both LiDAR packets and the scans (a
drive log merged with a session by the mcap library, one /tf_static channel) gets both the
sync checks and the calibration checks. Calibration is behind the policy: without a
calibration check the scans are never calibrated.
"""

from __future__ import annotations

import heapq
import json
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from typer.testing import CliRunner

from syncaudit.calib import CalibConfig, calibrate_log
from syncaudit.cli import app
from syncaudit.fleet.gate import GateOptions, run_gate
from syncaudit.fleet.policy import parse_policy

from .conftest import THREE_CAMERAS

TOLERANCE = {"rotation_deg": {"max": 0.3}, "translation_cm": {"max": 2.0}}
POLICY: dict[str, Any] = {
    "defaults": {
        "camera": {"error_mean_us": {"max": 5000}, "error_var_us2": {"max": 1e8}},
        "calibration": TOLERANCE,
    }
}
STOPS = "8"
TIMEOUT_S = 120.0
"""Per log: a calibration takes seconds; a deadlocked worker fails the test, not CI."""


def _simulate(out: Path, *extra: str) -> dict[str, Any]:
    """A 32-beam turntable session written by the command line; returns its truth."""
    result = CliRunner().invoke(
        app, ["simulate", "calib", str(out), "--stops", STOPS, "--seed", "3", *extra]
    )
    assert result.exit_code == 0, result.output
    truth: dict[str, Any] = json.loads(Path(f"{out}.truth.json").read_text())
    return truth


def _merge(out: Path, *logs: Path) -> None:
    """One MCAP holding every message of `logs` in log-time order (channels by topic)."""
    with out.open("wb") as handle:
        writer = Writer(handle, compression=CompressionType.ZSTD)
        writer.start("ros2", "syncaudit-test-merge")
        schemas: dict[tuple[str, bytes], int] = {}
        channels: dict[str, int] = {}
        streams = []
        for index, log in enumerate(logs):
            reader = make_reader(log.open("rb"))
            streams.append(
                (m.log_time, index, m.sequence, s, c, m) for s, c, m in reader.iter_messages()
            )
        for _, _, _, schema, channel, message in heapq.merge(*streams, key=lambda x: x[:3]):
            assert schema is not None
            key = (schema.name, schema.data)
            if key not in schemas:
                schemas[key] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.topic not in channels:
                channels[channel.topic] = writer.register_channel(
                    channel.topic, channel.message_encoding, schemas[key], channel.metadata
                )
            writer.add_message(
                channels[channel.topic], message.log_time, message.data, message.publish_time
            )
        writer.finish()


@pytest.fixture(scope="module")
def sessions(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    root = tmp_path_factory.mktemp("calib_gate")
    # One session as a ROS 1 bag (sensor_msgs/PointCloud2, no metadata), one as MCAP.
    good, bad = root / "session_good.bag", root / "session_bad.mcap"
    truths = {
        "good": _simulate(good),  # the rear LiDAR's recorded extrinsic off by 0.05 deg, 0.3 cm
        "bad": _simulate(bad, "--rotation-error-deg", "1.0", "--translation-error-cm", "5"),
    }
    # Calibrated here too: the gate's values must be the library's, and this process's
    # OpenMP runtime has now run, as in a program that calibrates and then calls run_gate
    # (workers forked from such a process deadlocked: they start fresh now).
    direct = calibrate_log(good, CalibConfig())
    drive = root / "drive_with_scans.mcap"
    _merge(drive, THREE_CAMERAS, bad)
    (root / "drive_with_scans.mcap.rig.yaml").write_text(
        Path(f"{THREE_CAMERAS}.rig.yaml").read_text()
    )
    return {
        "root": root,
        "good": good,
        "bad": bad,
        "drive": drive,
        "truths": truths,
        "direct": direct,
    }


def test_sessions_are_judged_on_their_calibration_checks(
    sessions: dict[str, Any], tmp_path: Path
) -> None:
    run = run_gate(
        [str(sessions["good"]), str(sessions["bad"]), str(sessions["drive"])],
        parse_policy(POLICY, "p"),
        GateOptions(jobs=2, html_dir=tmp_path / "html", timeout_s=TIMEOUT_S),
    )
    logs = {Path(log.path).name: log for log in run.logs}
    good, bad = logs["session_good.bag"], logs["session_bad.mcap"]
    assert good.verdict == "pass", good.error or good.checks
    assert bad.verdict == "fail" and run.exit_code == 10
    for log in (good, bad):
        assert log.error is None and {c.scope for c in log.checks} == {"calibration"}
        assert {(c.subject, c.check) for c in log.checks} == {
            ("/lidar/rear/points", "rotation_deg"),
            ("/lidar/rear/points", "translation_cm"),
        }
    # The measured differences are the recorded errors the simulator wrote in the truth.
    for name, log in (("good", good), ("bad", bad)):
        error = sessions["truths"][name]["lidars"][1]["recorded_error"]
        values = {c.check: c.value for c in log.checks}
        assert values["rotation_deg"] == pytest.approx(error["relative_rotation_deg"], abs=0.1)
        assert values["translation_cm"] == pytest.approx(error["relative_translation_cm"], abs=1.0)
    (ext,) = sessions["direct"].extrinsics
    assert {c.check: c.value for c in good.checks} == pytest.approx(
        {"rotation_deg": ext.rotation_diff_deg, "translation_cm": ext.translation_diff_cm},
        rel=1e-6,  # OpenMP sums in GICP: the last digits vary from run to run
    )
    assert all(c.passed for c in good.checks)
    assert not any(c.passed for c in bad.checks)
    assert "limit <= 0.3 deg" in next(c.message for c in bad.checks if c.check == "rotation_deg")

    # Packets, cameras and scans: the sync checks and the calibration checks both judge it
    # (and the file's condition, as every audited log).
    drive = logs["drive_with_scans.mcap"]
    scopes = {c.scope for c in drive.checks}
    assert scopes == {"camera", "lidar", "calibration", "log"}, drive.error
    assert {c.check for c in drive.checks if c.scope == "log"} == {
        "truncated",
        "damaged_messages",
        "missing_index",
    }
    assert drive.camera_count == 3
    failed = [(c.scope, c.check) for c in drive.failed_checks]
    assert failed == [("calibration", "rotation_deg"), ("calibration", "translation_cm")]
    assert drive.verdict == "fail"

    # Reports: a session's holds its calibration; the drive log's its audit and calibration.
    session_page = Path(good.report or "").read_text()
    assert 'class="sa-calib"' in session_page and "Policy checks" in session_page
    drive_page = Path(drive.report or "").read_text()
    assert 'class="sa-calib"' in drive_page and "rear_left" in drive_page


def test_calibration_is_behind_the_policy_switch(sessions: dict[str, Any]) -> None:
    """Without a calibration check nothing is calibrated: a session cannot be judged (an
    error row saying how to switch it on), a drive log with scans gets its sync checks."""
    sync_only = {"defaults": {"camera": POLICY["defaults"]["camera"]}}
    run = run_gate(
        [str(sessions["bad"]), str(sessions["drive"])],
        parse_policy(sync_only, "p"),
        GateOptions(jobs=2, timeout_s=TIMEOUT_S),
    )
    logs = {Path(log.path).name: log for log in run.logs}
    session = logs["session_bad.mcap"]
    assert session.verdict == "error" and session.error_code == 7
    assert "no LiDAR packets" in (session.error or "")
    assert "calibration: rotation_deg / translation_cm" in (session.error or "")
    drive = logs["drive_with_scans.mcap"]
    assert drive.verdict == "pass"
    assert {c.scope for c in drive.checks} == {"camera", "lidar", "log"}  # log: its condition
    # Switched on for one vehicle only: that vehicle's session is calibrated.
    per_vehicle = {
        **sync_only,
        "vehicle_pattern": r"(?P<vehicle>session)_bad",
        "vehicles": {"session": {"calibration": TOLERANCE}},
    }
    run = run_gate(
        [str(sessions["bad"])],
        parse_policy(per_vehicle, "p"),
        GateOptions(jobs=1, timeout_s=TIMEOUT_S),
    )
    (log,) = run.logs
    assert log.verdict == "fail" and {c.scope for c in log.checks} == {"calibration"}
