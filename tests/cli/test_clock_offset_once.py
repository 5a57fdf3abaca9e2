"""One host-minus-sensor clock offset per LiDAR: the same in table, warning and JSON (issue 23)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from syncaudit.cli import app

runner = CliRunner()


def test_vlp32_offset_is_one_number_everywhere(lidar_data: Path, tmp_path: Path) -> None:
    """Was +51.668702 s (the raw median, with t1) in the table, +51.668459 s in the warning."""
    log = lidar_data / "velodyne_vlp32" / "1713492677464078412"
    if not log.exists():
        pytest.skip("velodyne_vlp32 recording absent")
    out = tmp_path / "a.json"
    result = runner.invoke(app, ["audit", str(log), "--json-out", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["clock_offset_s"] == data["lidar"]["clock_offset_s"]
    assert data["clock_offset_s"] == pytest.approx(51.668459, abs=1e-6)
    shown = set(re.findall(r"[+-]\d+\.\d{6} s", result.output))
    assert shown == {"+51.668459 s"}, result.output
    info = runner.invoke(app, ["info", str(log), "--json"])
    (lidar,) = json.loads(info.stdout)["lidars"]
    assert lidar["clock_offset_s"] == data["clock_offset_s"]  # no triggers: the same floor
