"""`audit --calibration` takes the calibration of the audited log only (or says why not)."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path

from typer.testing import CliRunner, Result

from syncaudit.calib.result import CalibrationResult
from syncaudit.cli import app
from syncaudit.fleet.inputs import fingerprint
from syncaudit.report.calibration_log import IDENTITY_KEY, calibration_mismatch, log_identity

SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"
THREE_CAMERAS = SAMPLES / "vlp16_three_cameras.mcap"
SHORT = SAMPLES / "vlp16_short.bag"
Load = Callable[[str], CalibrationResult]


def test_a_copied_log_is_the_same_log_and_another_is_not(tmp_path: Path) -> None:
    copy = tmp_path / "moved.mcap"
    shutil.copyfile(THREE_CAMERAS, copy)
    doc = {"log": str(THREE_CAMERAS), IDENTITY_KEY: log_identity(1, fingerprint(THREE_CAMERAS))}
    assert calibration_mismatch(doc, copy, fingerprint(copy)) is None
    why = calibration_mismatch(doc, SHORT, fingerprint(SHORT))
    assert why is not None and "another log" in why


def test_without_an_identity_only_the_same_path_is_accepted(tmp_path: Path) -> None:
    doc = {"log": str(THREE_CAMERAS)}
    assert calibration_mismatch(doc, THREE_CAMERAS, "f") is None
    (tmp_path / "l.mcap").symlink_to(THREE_CAMERAS)
    assert calibration_mismatch(doc, tmp_path / "l.mcap", "f") is None  # one file, two names
    why = calibration_mismatch(doc, SHORT, "f")
    assert why is not None and "records no fingerprint" in why


def _calibration_of(log: Path, tmp_path: Path, calibration: Load) -> Path:
    """A saved calibration result (the turntable's) claiming to be of `log`."""
    data = calibration("calib_turntable_32").to_json_dict()
    data["log"] = str(log)
    data[IDENTITY_KEY] = log_identity(log.stat().st_size, fingerprint(log))
    out = tmp_path / "cal.json"
    out.write_text(json.dumps(data))
    return out


def test_cli_refuses_another_logs_calibration_unless_told(
    tmp_path: Path, calibration: Load
) -> None:
    cal = _calibration_of(SHORT, tmp_path, calibration)
    html = tmp_path / "r.html"
    argv = ["audit", str(THREE_CAMERAS), "--html", str(html), "--calibration", str(cal)]
    refused = CliRunner().invoke(app, argv)
    assert refused.exit_code == 6, refused.output
    assert "calibration of another log" in refused.output
    assert "--calibration-any-log" in refused.output and "Traceback" not in refused.output
    assert not html.exists()
    told = CliRunner().invoke(app, [*argv, "--calibration-any-log"])
    assert told.exit_code == 0, told.output
    assert html.is_file()


def _audit_with(log: Path, html: Path, calibration: Path) -> Result:
    """`audit LOG --html H --calibration C` with the three-camera rig."""
    return CliRunner().invoke(
        app,
        ["audit", str(log), "--rig", f"{THREE_CAMERAS}.rig.yaml", "--html", str(html),
         "--calibration", str(calibration)],
    )  # fmt: skip


def test_cli_takes_the_calibration_of_a_moved_copy(tmp_path: Path, calibration: Load) -> None:
    cal = _calibration_of(THREE_CAMERAS, tmp_path, calibration)
    moved = tmp_path / "moved.mcap"
    shutil.copyfile(THREE_CAMERAS, moved)
    html = tmp_path / "r.html"
    result = _audit_with(moved, html, cal)
    assert result.exit_code == 0, result.output
    assert "mounts" in html.read_text()


def test_cli_refuses_a_calibration_that_gives_a_key_twice(
    tmp_path: Path, calibration: Load
) -> None:
    """Two values for one key: pydantic would keep the last silently, a reader the first."""
    cal = _calibration_of(THREE_CAMERAS, tmp_path, calibration)
    text = cal.read_text()
    assert text.startswith("{") and '"passed": ' in text
    cal.write_text('{"passed": true, ' + text[1:])  # `passed` appears again further on
    html = tmp_path / "r.html"
    result = _audit_with(THREE_CAMERAS, html, cal)
    assert result.exit_code == 6, result.output
    assert "key 'passed' given twice" in result.output and "Traceback" not in result.output
    assert not html.exists()
