"""`audit x.mcap` takes the rig `x.mcap.rig.yaml` beside the log, as `gate` does (issue 23)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from typer.testing import CliRunner

from syncaudit.cli import app

REPO = Path(__file__).resolve().parents[2]
LOG = REPO / "sample_logs" / "vlp16_three_cameras.mcap"
runner = CliRunner()


def _audit_json(*args: str) -> tuple[dict[str, object], str]:
    result = runner.invoke(app, ["audit", *args, "--json"])
    assert result.exit_code in (0, 10), result.output
    return json.loads(result.stdout), result.stderr


def test_the_rig_beside_the_log_is_used_and_said() -> None:
    data, said = _audit_json(str(LOG))
    assert "using rig vlp16_three_cameras.mcap.rig.yaml beside the log" in said
    assert data["guessed"] == []
    front = next(c for c in data["cameras"] if c["camera"] == "front")  # type: ignore[union-attr]
    assert front["theta_deg"] == 60.0  # the rig's zero azimuth 300, camera at 0


def test_no_rig_forces_the_guess() -> None:
    data, said = _audit_json(str(LOG), "--no-rig")
    assert "beside the log" not in said
    assert any("LiDAR topic" in g for g in data["guessed"])  # type: ignore[union-attr]


def test_rig_overrides_the_one_beside(tmp_path: Path) -> None:
    other = tmp_path / "other.rig.yaml"
    text = (LOG.parent / (LOG.name + ".rig.yaml")).read_text()
    other.write_text(text.replace("zero_azimuth_deg: 300.0", "zero_azimuth_deg: 330.0"))
    data, said = _audit_json(str(LOG), "--rig", str(other))
    assert "beside the log" not in said
    front = next(c for c in data["cameras"] if c["camera"] == "front")  # type: ignore[union-attr]
    assert front["theta_deg"] == 30.0


def test_no_rig_and_rig_together_are_a_usage_error(tmp_path: Path) -> None:
    copy = tmp_path / LOG.name
    shutil.copy(LOG, copy)
    result = runner.invoke(app, ["audit", str(copy), "--no-rig", "--rig", str(tmp_path / "r")])
    assert result.exit_code == 64
    assert result.output.strip().splitlines() == ["error: --rig and --no-rig: give one"]
