"""Method B end to end on simulated sessions, scored against the truth sidecar.

The fast subset runs one seed of every case of the simulator's `MATRIX` (turntable and
driving sessions: translation between stops, motion-distorted scans, roof/bumper/diagonal
mounts, 16-128 beams, organised clouds, two-level tf chains, odometry) plus the refusals.
Each matrix session is simulated and calibrated once per module, two at a time in
spawned workers, with 8 stops and 2-4 moving scans per move (`FAST_STOPS`,
`FAST_MOVING_SCANS`; a case in `SEEDS` runs that seed's 12-stop session, a regression); `benchmarks/bench_calib.py` runs 12 stops, 10-18 moving scans and
10 seeds per case. Tolerances per beam class are the
issue's: 16 beams 0.3 deg / 2 cm (sparse rings), 32 and 64 beams 0.1 deg / 1 cm,
128 beams 0.05 deg / 0.5 cm.
"""

from __future__ import annotations

import io
import json
import math
import multiprocessing
import os
import re
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from rich.console import Console

from syncaudit.calib import (
    CalibConfig,
    CalibrationResult,
    PoseGraphConfig,
    RegistrationConfig,
    calibrate_log,
    se3,
)
from syncaudit.calib.settings import AlignmentLimits, load_config
from syncaudit.errors import ConfigError, NoDataError
from syncaudit.report.calib_section import html_section, render_calibration
from syncaudit.report.report_page import render_calibration_html
from syncaudit.simulate.calib_config import CalibSceneConfig, calib_scene_config, rig_preset
from syncaudit.simulate.calib_session import MATRIX, matrix_tolerance, simulate_calib_session
from syncaudit.writers.atomic import write_text_atomic

FAST_STOPS = 8
"""Stops per driving session in the fast subset (the benchmark runs 12)."""


def error_to_truth(result: CalibrationResult, truth: dict[str, Any]) -> tuple[float, float]:
    """Rotation (deg) and translation (cm) of the calibrated second extrinsic vs the truth."""
    (ext,) = result.extrinsics
    rear = next(x for x in truth["lidars"] if x["topic"] == ext.topic)
    assert ext.result is not None, result.reason
    true = np.array(rear[f"true_{truth['reference_lidar']}_from_lidar"]["matrix"])
    rot_deg, trans_m = se3.transform_difference(true, np.array(ext.result.matrix))
    return rot_deg, trans_m * 100.0


FAST_MOVING_SCANS = (2, 4)
"""Sweeps recorded while driving between stops in the fast subset (the benchmark and the
issue's sessions: 10-18). Stops are found from still scans only, and the matrix's stops
pin the extrinsics, and the moving scans join the graph only when asked
(`MovingScansConfig.use`, off by default); fewer of them change what the stop detection must reject
(faster, more distorted sweeps) but not what is calibrated; the simulation and reading
time halve."""


SEEDS = {"drive-64-bumper": 2}
"""Cases whose fast-subset session is not seed 0 (and runs 12 stops): a session that once
missed its target stands for its case, one session instead of two. drive-64-bumper seed 2
(12 stops: the loop closes): the coarse motion 5->6 is 1.15 m wrong and the front LiDAR's
5-6 alignment, seeded there, converged 1.39 m off and was accepted, so the front map held
stops 6-10 1.38 m off (1.7 cm calibration error with these moving scans, 1.21 cm with the
benchmark's)."""


FAST_CASES = [name for name in MATRIX if not name.startswith("parking-")] + ["parking-64-bumper"]
"""The matrix cases the fast subset runs: all but four of the parking-lot cases, which
`benchmarks/bench_calib.py` runs (with them the module's sessions took over its 1200 s
timeout on the shared machine at load 18-22); parking-64-bumper is issue 29's failing kind."""


def _case_config(name: str) -> CalibSceneConfig:
    """One session of a matrix case as the fast subset runs it (seed 0 unless `SEEDS`)."""
    case = MATRIX[name]
    stops = 12 if case["motion"] == "turntable" or name in SEEDS else FAST_STOPS
    config = calib_scene_config(seed=SEEDS.get(name, 0), **{**case, "n_stops": stops})
    if case["motion"] == "drive":
        config = config.model_copy(update={"moving_scans_range": FAST_MOVING_SCANS})
    return config


@pytest.fixture(scope="module")
def matrix_runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """Simulate and calibrate one session of every matrix case once for the module.

    Two worker processes (spawned: small_gicp's OpenMP state must not be forked; they run
    the library's own functions) halve the wall time on a 2-core machine; each case is a
    pure function of its seed, so the results do not depend on the split.
    """
    root = tmp_path_factory.mktemp("calib")
    workers = max(1, min(2, os.cpu_count() or 1))
    context = multiprocessing.get_context("spawn")
    configs = {name: _case_config(name) for name in FAST_CASES}
    paths = {name: root / f"{name}.mcap" for name in configs}
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        sims = {
            name: pool.submit(simulate_calib_session, paths[name], config)
            for name, config in configs.items()
        }
        calibs = {
            name: pool.submit(calibrate_log, paths[name], CalibConfig())
            for name in configs
            if sims[name].result() is not None
        }
        return {name: (paths[name], sims[name].result(), calibs[name].result()) for name in configs}


@pytest.mark.parametrize("case", FAST_CASES)
def test_matrix_case_meets_its_tolerance(matrix_runs: dict[str, Any], case: str) -> None:
    _path, truth, result = matrix_runs[case]
    assert result.calibratable, result.reason
    rot_deg, trans_cm = error_to_truth(result, truth)
    max_rot, max_cm = matrix_tolerance(MATRIX[case]["beams"])
    assert rot_deg <= max_rot and trans_cm <= max_cm, (case, rot_deg, trans_cm)
    # The recorded error (0.05 deg / 0.3 cm) is within the limits: validation passes.
    assert result.passed
    n = len(truth["stops"])
    assert all(sum(s.used for s in lidar.stops) >= n // 2 for lidar in result.lidars)


def test_map_pairs_are_built_from_the_stops_both_graphs_hold(
    matrix_runs: dict[str, Any],
) -> None:
    """Each anchor's map-to-map alignment compares the two LiDARs over the same stops, so
    a stop only one LiDAR's graph placed (perhaps through weak links) cannot bias it; the
    whole maps are aligned, after all of those, only when none of them was accepted as
    well constrained as a cross-scan alignment must be."""
    limits = CalibConfig().registration.limits

    def firm(pair: Any) -> bool:
        cond = pair.alignment.conditioning
        return (
            pair.result is not None
            and cond.translation_information >= limits.min_translation_information
            and cond.rotation_information >= limits.min_rotation_information
        )

    kinds = set()
    for case, (_path, _truth, result) in matrix_runs.items():
        for ext in result.baseline:  # the map pairs are the baseline's bridge
            assert ext.map_pairs, case
            assert all(p.anchor_stop in p.reference_stops for p in ext.map_pairs), case
            shared = [p for p in ext.map_pairs if p.reference_stops == p.lidar_stops]
            whole = [p for p in ext.map_pairs if p.reference_stops != p.lidar_stops]
            assert ext.map_pairs == shared + whole, case
            if any(firm(p) for p in shared):
                assert not whole, case
                used = [p for p in shared if firm(p)]
            else:
                used = [p for p in whole if p.result is not None]
            kinds.add(bool(whole))
            assert ext.result is not None and used, case
            if len(used) == 1 and used[0].result is not None:
                assert ext.result.matrix == used[0].result.matrix, case
    assert kinds == {True, False}  # the fast subset has both kinds


def test_a_wrong_coarse_link_is_caught_across_lidars(matrix_runs: dict[str, Any]) -> None:
    """The front LiDAR's 5-6 alignment disagrees with the rear's view of the same motion;
    aligned again from it, it fits better and lands right, and the calibration meets the
    64-beam target."""
    assert SEEDS["drive-64-bumper"] == 2
    _path, truth, result = matrix_runs["drive-64-bumper"]
    rot_deg, trans_cm = error_to_truth(result, truth)
    assert rot_deg <= 0.1 and trans_cm <= 1.0, (rot_deg, trans_cm)
    (note,) = [n for n in result.notes if n.startswith("cross-LiDAR check")]
    assert "/lidar/front/points 5->6 (139 cm from /lidar/rear/points" in note
    front = next(lidar for lidar in result.lidars if lidar.topic == "/lidar/front/points")
    pair = next(p for p in front.pairs if (p.first_stop, p.second_stop) == (5, 6))
    # The wrong one fitted at 2.3 cm with 30 % overlap; the one now kept fits better.
    after = pair.alignment.after
    assert after.rmse_cm is not None and after.rmse_cm < 2.0 and after.overlap > 0.32


def test_driving_stops_are_the_true_stops(matrix_runs: dict[str, Any]) -> None:
    """Stillness from scan-to-scan change finds every stop of every driving case, each
    inside its true window, whatever the mount (a bumper LiDAR sees mostly ground)."""
    for case in FAST_CASES:
        if MATRIX[case]["motion"] != "drive":
            continue
        _path, truth, result = matrix_runs[case]
        assert len(result.stops) == len(truth["stops"]), case
        slack = 110_000_000  # a scan at a stop's edge moves by well under a millimetre
        for stop, true_stop in zip(result.stops, truth["stops"], strict=True):
            assert true_stop["start_ns"] - slack <= stop.start_ns, case
            assert stop.end_ns <= true_stop["end_ns"] + slack, case
        assert any("taken while moving" in note for note in result.notes)
        for lidar in result.lidars:  # every moving scan accounted for, used or not
            report = lidar.moving_scans
            assert report is not None and report.seen > 0, case
            assert report.used + sum(report.rejected.values()) == report.seen, case


def test_odometry_seeds_the_motion(matrix_runs: dict[str, Any]) -> None:
    for case in ("drive-64-roof-odom", "drive-128-left-right"):
        _path, truth, result = matrix_runs[case]
        assert truth["odometry"]["final_drift_deg"] > 0.5  # the odometry really drifts
        assert any("odometry from" in note for note in result.notes), case


def test_validation_flags_a_recorded_extrinsic_off_by_1_deg_5_cm(tmp_path: Path) -> None:
    out = tmp_path / "bad.mcap"
    truth = simulate_calib_session(
        out,
        CalibSceneConfig(
            seed=4,
            lidars=rig_preset(32, rear_rotation_error_deg=1.0, rear_translation_error_cm=5.0),
        ),
    )
    result = calibrate_log(out, CalibConfig())
    (ext,) = result.extrinsics
    rel = truth["lidars"][1]["recorded_error"]
    assert ext.rotation_diff_deg == pytest.approx(rel["relative_rotation_deg"], abs=0.1)
    assert ext.translation_diff_cm == pytest.approx(rel["relative_translation_cm"], abs=1.0)
    assert not result.passed and not ext.passed and result.calibratable


def test_result_json_html_and_console(matrix_runs: dict[str, Any], tmp_path: Path) -> None:
    _path, _truth, result = matrix_runs["turntable-32-roof"]
    data = result.to_json_dict()
    assert json.loads(json.dumps(data)) == data
    assert data["calibratable"] and data["passed"]
    lidar = data["lidars"][0]
    assert {"stop", "stamp_ns", "angle_deg", "used", "reason"} <= set(lidar["stops"][0])
    pair = lidar["pairs"][0]
    assert {"before", "after", "accepted", "reason", "conditioning", "expected_overlap"} <= set(
        pair["alignment"]
    )
    assert 0.0 < pair["alignment"]["expected_overlap"] <= 1.0
    assert data["anchor_stops"][0] == data["reference_stop"]
    (ext,) = data["baseline"]  # the map pairs are the baseline's bridge
    assert ext["map_pairs"] and ext["map_pairs"][0]["anchor_stop"] == data["reference_stop"]
    out = tmp_path / "calib.json"
    write_text_atomic(out, json.dumps(data, indent=2) + "\n")
    assert json.loads(out.read_text()) == data
    assert [p.name for p in tmp_path.iterdir()] == ["calib.json"]
    html = html_section(result)
    assert html.startswith('<section class="sa-calib">') and html.endswith("</section>")
    assert "<script" not in html and "PASS" in html and "lidar_rear" in html
    assert "accepted" in html and "→" in html
    page = render_calibration_html(result)
    assert page.startswith("<!doctype html>") and html in page
    buffer = io.StringIO()
    render_calibration(result, Console(file=buffer, width=160))
    assert "PASS" in buffer.getvalue() and "lidar_rear" in buffer.getvalue()
    # Which estimate it is, with the joint graph's 1-sigma, in both renderings.
    assert result.joint is not None and result.joint.chosen
    sigma = result.joint.lidars[0]
    said = f"joint graph, 1-sigma {sigma.sigma_deg:.3f} deg / {sigma.sigma_cm:.2f} cm"
    assert said in buffer.getvalue().replace("\n", " ") and said in html


@pytest.fixture(scope="module")
def two_stops(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """A cheap session (16 beams, 2 stops: too few to calibrate) and its truth."""
    out = tmp_path_factory.mktemp("two") / "two.mcap"
    truth = simulate_calib_session(out, calib_scene_config(motion="drive", beams=16, n_stops=2))
    return out, truth


def test_extrinsics_file_replaces_tf_static(
    two_stops: tuple[Path, dict[str, Any]], tmp_path: Path
) -> None:
    """The file's extrinsics (here the true ones) replace /tf_static's (0.05 deg / 0.3 cm
    off) as the recorded ones the result reports and validates against. A session too
    short to calibrate is enough: the recorded extrinsics are read before anything else."""
    path, truth = two_stops
    entries = {
        lidar["frame_id"]: {
            "translation_m": lidar["true_base_from_lidar"]["translation_m"],
            "quaternion_xyzw": lidar["true_base_from_lidar"]["quaternion_xyzw"],
        }
        for lidar in truth["lidars"]
    }
    file = tmp_path / "extrinsics.yaml"
    file.write_text(yaml.safe_dump({"base_frame": "base_link", "extrinsics": entries}))
    result = calibrate_log(path, CalibConfig(extrinsics_file=file))
    assert result.extrinsics_source == str(file)
    (ext,) = result.extrinsics
    rear = next(x for x in truth["lidars"] if x["topic"] == ext.topic)
    from_file = np.array(ext.recorded.matrix)
    true = np.array(rear[f"true_{truth['reference_lidar']}_from_lidar"]["matrix"])
    tf_static = np.array(rear[f"recorded_{truth['reference_lidar']}_from_lidar"]["matrix"])
    assert np.allclose(from_file, true, atol=1e-6)
    assert se3.transform_difference(from_file, tf_static)[1] > 0.002
    default = calibrate_log(path, CalibConfig())
    assert np.allclose(np.array(default.extrinsics[0].recorded.matrix), tf_static, atol=1e-6)
    del entries["lidar_rear"]
    file.write_text(yaml.safe_dump({"extrinsics": entries}))
    with pytest.raises(NoDataError, match="lidar_rear"):
        calibrate_log(path, CalibConfig(extrinsics_file=file))


def test_free_motion_pose_graph(matrix_runs: dict[str, Any]) -> None:
    """Full SE(3) pose graphs (no flat-floor assumption) still meet the 32-beam target."""
    path, truth, _result = matrix_runs["turntable-32-roof"]
    result = calibrate_log(path, CalibConfig(pose_graph=PoseGraphConfig(motion="free")))
    rot_deg, trans_cm = error_to_truth(result, truth)
    assert rot_deg <= 0.1 and trans_cm <= 1.0


def test_too_few_stops_is_a_result_not_nothing_to_audit(
    two_stops: tuple[Path, dict[str, Any]],
) -> None:
    result = calibrate_log(two_stops[0], CalibConfig())
    assert not result.calibratable and result.reason is not None
    assert "has 2 stop(s) among" in result.reason and "at least 3" in result.reason
    assert json.loads(json.dumps(result.to_json_dict()))["calibratable"] is False


def test_log_and_config_errors(tmp_path: Path) -> None:
    small = [
        lidar.model_copy(update={"beams": 16, "horizontal_resolution_deg": 1.0})
        for lidar in rig_preset(16)
    ]
    log = tmp_path / "small.mcap"
    simulate_calib_session(log, CalibSceneConfig(n_stops=3, lidars=small))
    with pytest.raises(NoDataError, match="no PointCloud2 topic /nope"):
        calibrate_log(log, CalibConfig(lidar_topics=["/nope", "/lidar/rear/points"]))
    with pytest.raises(NoDataError, match="two or more LiDARs"):
        calibrate_log(
            log,
            CalibConfig(lidar_topics=["/lidar/front/points", "/lidar/rear/points"]).model_copy(
                update={"lidar_topics": ["/lidar/front/points"]}
            ),
        )
    no_tf = tmp_path / "no_tf.mcap"
    simulate_calib_session(no_tf, CalibSceneConfig(n_stops=3, lidars=small, tf_topic="/tf_other"))
    with pytest.raises(NoDataError, match="no recorded extrinsics"):
        calibrate_log(no_tf, CalibConfig())
    with pytest.raises(ConfigError, match="coarse_voxel_m"):
        RegistrationConfig(voxel_m=1.0, coarse_voxel_m=0.5)
    with pytest.raises(ConfigError, match="not increase"):
        AlignmentLimits(correspondence_stages_m=(0.2, 1.0))
    with pytest.raises(ConfigError, match="two or more"):
        CalibConfig(lidar_topics=["/a"])
    bad = tmp_path / "calib.yaml"
    bad.write_text("registration: {voxel_m: -1}\n")
    with pytest.raises(ConfigError, match="voxel_m"):
        load_config(bad, CalibConfig)
    nested = tmp_path / "limits.yaml"
    nested.write_text("registration: {limits: {min_overlap_ratio: 0.5}}\n")
    loaded: CalibConfig = load_config(nested, CalibConfig)
    assert loaded.registration.limits.min_overlap_ratio == 0.5


def _footprint_distance_m(xy_m: np.ndarray, objects: list[dict[str, Any]]) -> np.ndarray:
    """Distance in the ground plane from each point to the nearest object's footprint
    (0 inside it): where a top-view point of the true scene must lie."""
    best = np.full(xy_m.shape[0], np.inf)
    for obj in objects:
        if obj["type"] == "pole":
            d = np.linalg.norm(xy_m - np.array(obj["center_xy_m"]), axis=1) - obj["radius_m"]
        else:
            yaw = math.radians(obj["yaw_deg"])
            rot = np.array([[math.cos(yaw), math.sin(yaw)], [-math.sin(yaw), math.cos(yaw)]])
            local = (xy_m - np.array(obj["center_m"][:2])) @ rot.T
            outside = np.maximum(np.abs(local) - np.array(obj["size_m"][:2]) / 2.0, 0.0)
            d = np.linalg.norm(outside, axis=1)
        best = np.minimum(best, np.maximum(d, 0.0))
    return best


def _top_view_in_world(
    top: Any, truth: dict[str, Any], shift_m: float = 0.0
) -> dict[int, np.ndarray]:
    """Each stop's top-view points in the simulator's world, through the true vehicle pose
    at the stop the view is anchored at (the frame text names it)."""
    match = re.match(r"base_link at stop (\d+), ", top.frame)
    assert match is not None, top.frame
    world_from_base = np.array(truth["stops"][int(match[1])]["world_from_base"]["matrix"])
    out = {}
    for stop in top.stops:
        xy = np.c_[stop.x_m, stop.y_m] + shift_m
        out[stop.stop] = xy @ world_from_base[:2, :2].T + world_from_base[:2, 3]
    return out


def test_top_view_places_every_stop_on_the_true_scene(matrix_runs: dict[str, Any]) -> None:
    """Each LiDAR's top view puts every used stop's points on the scene's objects (the
    poses and the mount are right), the same wall seen from several stops draws one line,
    and the JSON stays small."""
    _path, truth, result = matrix_runs["drive-32-left-right"]
    objects = truth["scene"]["objects"]
    for lidar in result.lidars:
        top = lidar.top_view
        assert top is not None and top.cell_m == pytest.approx(0.2)
        assert [s.stop for s in top.stops] == [s.stop for s in lidar.stops if s.used]
        via = "recorded" if lidar.topic == result.reference_topic else "calibrated"
        assert top.frame.endswith(f"{lidar.frame_id} placed by the {via} extrinsic"), top.frame
        world = _top_view_in_world(top, truth)
        for points in top.stops:
            # Whole centimetres, one point per 0.2 m cell.
            xy_cm = np.round(np.c_[points.x_m, points.y_m] * 100.0)
            assert np.allclose(xy_cm / 100.0, np.c_[points.x_m, points.y_m], rtol=0, atol=1e-9)
            cells = np.floor_divide(xy_cm.astype(np.int64), 20)
            assert len(np.unique(cells, axis=0)) == len(cells)
        for stop, xy in world.items():
            assert xy.shape[0] >= 50, (lidar.topic, stop)
            on_scene = float(np.mean(_footprint_distance_m(xy, objects) < 0.05))
            assert on_scene > 0.97, (lidar.topic, stop, on_scene)
        # The check can fail: the same points 5 cm off (in x and y) are not on the scene.
        shifted = _top_view_in_world(top, truth, shift_m=0.05)
        off = np.concatenate([_footprint_distance_m(xy, objects) for xy in shifted.values()])
        assert float(np.mean(off < 0.05)) < 0.9
        # Each wall seen from several stops: the stops' mean offsets from its face agree.
        for wall in (o for o in objects if o["type"] == "wall"):
            yaw = math.radians(wall["yaw_deg"])
            thin = 0 if wall["size_m"][0] < wall["size_m"][1] else 1
            axis = np.array(
                [math.cos(yaw), math.sin(yaw)] if thin == 0 else [-math.sin(yaw), math.cos(yaw)]
            )
            half = wall["size_m"][thin] / 2.0
            offsets = []
            for xy in world.values():
                across = np.abs((xy - np.array(wall["center_m"][:2])) @ axis) - half
                near = (_footprint_distance_m(xy, [wall]) < 0.3) & (across > -half)
                if near.sum() >= 20:
                    offsets.append(float(np.mean(across[near])))
            if len(offsets) >= 2:
                assert max(offsets) - min(offsets) < 0.03, (lidar.topic, offsets)
    # The written file (indented): measured 198 KB for these 8 stops, 25 KB per stop.
    size = len(json.dumps(result.to_json_dict(), indent=2))
    assert size < 35_000 * len(truth["stops"]), size
