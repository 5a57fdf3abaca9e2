"""Stop detection and the early refusals (calib.selection) on simulated sessions."""

from __future__ import annotations

import math
import re
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from syncaudit.calib import (
    CalibConfig,
    calibrate_log,
)
from syncaudit.report.calib_section import html_section
from syncaudit.simulate.calib_config import CalibSceneConfig, calib_scene_config, rig_preset
from syncaudit.simulate.calib_session import simulate_calib_session


@pytest.mark.parametrize("scene", ["ground_and_wall", "corridor"])
def test_degenerate_scene_is_refused_early_naming_the_free_direction(
    tmp_path: Path, scene: Any
) -> None:
    """Ground and one wall, or a corridor: sliding along the walls is unobservable; the
    scene is refused on that, within seconds, naming the free direction."""
    out = tmp_path / "wall.mcap"
    truth = simulate_calib_session(
        out, calib_scene_config(motion="drive", beams=16, scene=scene, n_stops=5)
    )
    start = time.process_time()
    result = calibrate_log(out, CalibConfig())
    cpu_s = time.process_time() - start
    assert not result.calibratable and not result.passed
    assert result.reason is not None and "degenerate scene" in result.reason
    assert all(ext.result is None and not ext.calibrated for ext in result.extrinsics)
    # The named free direction is the walls' run, seen from the vehicle at some stop.
    assert truth["scene"]["objects"][0]["type"] == "wall"
    assert "along (" in result.reason
    assert cpu_s < 10.0, cpu_s
    assert "NOT CALIBRATABLE" in html_section(result)
    # The same direction, structured: along the walls (world) seen from the named stop.
    deg = result.degeneracy
    assert deg is not None and deg.kind == "translation"
    assert deg.information < deg.limit == pytest.approx(0.02)
    match = re.fullmatch(r"base_link at stop (\d+)", deg.frame)
    assert match is not None, deg.frame
    world_from_base = np.array(truth["stops"][int(match[1])]["world_from_base"]["matrix"])
    direction = world_from_base[:3, :3] @ np.array(deg.direction)
    wall_yaw = math.radians(truth["scene"]["objects"][0]["yaw_deg"])
    # ground_and_wall boxes are long along their y axis, corridor walls along x.
    along = (
        np.array([-math.sin(wall_yaw), math.cos(wall_yaw), 0.0])
        if scene == "ground_and_wall"
        else np.array([math.cos(wall_yaw), math.sin(wall_yaw), 0.0])
    )
    angle_deg = math.degrees(math.acos(min(1.0, abs(float(direction @ along)))))
    assert angle_deg < 5.0, (scene, angle_deg)
    assert f"({deg.direction[0]:.2f}, {deg.direction[1]:.2f}, {deg.direction[2]:.2f})" in (
        result.reason
    )
    assert all(lidar.top_view is None for lidar in result.lidars)
    assert result.to_json_dict()["degeneracy"]["kind"] == "translation"


def test_turntable_stops_are_found_among_moving_scans(tmp_path: Path) -> None:
    out = tmp_path / "turning.mcap"
    truth = simulate_calib_session(
        out,
        CalibSceneConfig(
            seed=1, n_stops=8, scans_per_stop=3, turning_scans=2, lidars=rig_preset(32)
        ),
    )
    result = calibrate_log(out, CalibConfig())
    assert len(result.stops) == 8
    for stop, true_stop in zip(result.stops, truth["stops"], strict=True):
        assert true_stop["start_ns"] <= stop.start_ns <= stop.end_ns <= true_stop["end_ns"]
    for lidar in result.lidars:
        assert [s.static_scans for s in lidar.stops] == [3] * 8
        for use, true_stop in zip(lidar.stops, truth["stops"], strict=True):
            expected = (
                true_stop["yaw_deg"] - truth["stops"][result.reference_stop or 0]["yaw_deg"] + 180
            ) % 360 - 180
            assert use.angle_deg == pytest.approx(expected, abs=0.5)
    assert any("while moving" in note for note in result.notes)
    assert result.calibratable
