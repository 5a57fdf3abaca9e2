"""`syncaudit simulate calib`: the session options reach the simulator; bad values exit 64."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from syncaudit.calib import io
from syncaudit.cli import app

runner = CliRunner()


def test_drive_session_with_every_option(tmp_path: Path) -> None:
    out = tmp_path / "drive.mcap"
    made = runner.invoke(
        app,
        [
            "simulate", "calib", str(out), "--motion", "drive", "--mount", "bumper_front_rear",
            "--beams", "16", "--stops", "2", "--organized", "second", "--tf-chain", "sensor_kit",
            "--odometry", "both", "--range-noise-m", "0.02", "--seed", "3",
        ],
    )  # fmt: skip
    assert made.exit_code == 0, made.output
    assert "drive, 2 stops, 16-beam LiDARs bumper_front_rear, yard" in made.stdout
    truth = json.loads(Path(f"{out}.truth.json").read_text())
    assert truth["odometry"] is not None
    edges = io.read_static_transforms(out, "/tf_static")
    assert "sensor_kit_base_link" in {edge.parent for edge in edges}
    assert set(io.pointcloud_topics(out)) == {lidar["topic"] for lidar in truth["lidars"]}


def test_degenerate_is_an_alias_of_the_ground_and_wall_scene(tmp_path: Path) -> None:
    out = tmp_path / "wall.mcap"
    made = runner.invoke(app, ["simulate", "calib", str(out), "--stops", "2", "--degenerate"])
    assert made.exit_code == 0, made.output
    truth = json.loads(Path(f"{out}.truth.json").read_text())
    assert [o["type"] for o in truth["scene"]["objects"]] == ["wall"]


@pytest.mark.parametrize(
    ("args", "names"),
    [
        (["--beams", "24"], "--beams must be one of 16|32|64|128"),
        (["--mount", "trunk"], "--mount must be one of"),
        (["--motion", "fly"], "--motion"),
        (["--organized", "all"], "--organized"),
        (["--tf-chain", "deep"], "--tf-chain"),
        (["--odometry", "gps"], "--odometry"),
        (["--scene", "forest"], "--scene"),
        (["--range-noise-m", "-1"], "--range-noise-m"),
        (["--scene", "corridor", "--degenerate"], "--degenerate conflicts with --scene"),
        (["--motion", "drive", "--scans-per-stop", "3"], "--scans-per-stop only apply"),
    ],
)
def test_bad_values_are_usage_errors(tmp_path: Path, args: list[str], names: str) -> None:
    result = runner.invoke(app, ["simulate", "calib", str(tmp_path / "o.mcap"), *args])
    assert result.exit_code == 64, result.output
    assert result.stderr.startswith("error: ") and result.stderr.count("\n") == 1
    assert names in result.stderr and "Traceback" not in result.output
    assert not list(tmp_path.iterdir())
