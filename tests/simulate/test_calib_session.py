"""The simulated turntable session: real ROS 2 messages, honest truth, exact geometry."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from syncaudit.calib import se3
from syncaudit.calib.io import iter_scans, read_static_transforms
from syncaudit.errors import ConfigError
from syncaudit.logs import open_log
from syncaudit.simulate.calib_config import (
    CalibSceneConfig,
    LidarSimConfig,
    SceneConfig,
    rig_preset,
)
from syncaudit.simulate.calib_session import simulate_calib_session, truth_path
from syncaudit.writers.provenance import WRITTEN_BY


def _small(**overrides: Any) -> CalibSceneConfig:
    """A cheap session: 16 coarse beams, few stops."""
    lidars = [
        lidar.model_copy(update={"beams": 16, "horizontal_resolution_deg": 1.0})
        for lidar in rig_preset(16)
    ]
    return CalibSceneConfig(**{"n_stops": 4, "lidars": lidars, **overrides})


def _matrix(entry: dict[str, Any]) -> np.ndarray:
    return np.array(entry["matrix"])


def test_log_has_real_pointcloud2_and_tf_static(tmp_path: Path) -> None:
    out = tmp_path / "session.mcap"
    truth = simulate_calib_session(out, _small(scans_per_stop=2, turning_scans=1))
    saved = json.loads(truth_path(out).read_text())
    assert saved.pop("written_by") == WRITTEN_BY  # the tool's mark, first key
    assert saved == truth
    assert sorted(p.name for p in tmp_path.iterdir()) == ["session.mcap", "session.mcap.truth.json"]
    with open_log(out) as log:
        topics = log.topics
        assert topics["/tf_static"].msgtype == "tf2_msgs/msg/TFMessage"
        for lidar in truth["lidars"]:
            info = topics[lidar["topic"]]
            assert info.msgtype == "sensor_msgs/msg/PointCloud2"
            assert info.has_definition
            assert info.count == 4 * 2 + 3
        raw = next(iter(log.messages(topics=["/lidar/front/points"])))
        msg: Any = log.deserialize(raw)
        assert [f.name for f in msg.fields] == ["x", "y", "z", "intensity", "ring", "time"]
        assert msg.point_step == 22 and msg.header.frame_id == "lidar_front"
    # /tf_static carries the recorded (perturbed) extrinsics, exactly.
    edges = {e.child: e for e in read_static_transforms(out, "/tf_static")}
    for lidar in truth["lidars"]:
        edge = edges[lidar["frame_id"]]
        assert edge.parent == "base_link"
        assert np.allclose(
            edge.parent_from_child, _matrix(lidar["recorded_base_from_lidar"]), atol=1e-12
        )
    rear = truth["lidars"][1]
    rot_deg, trans_m = se3.transform_difference(
        _matrix(rear["true_base_from_lidar"]), _matrix(rear["recorded_base_from_lidar"])
    )
    assert rot_deg == pytest.approx(rear["recorded_error"]["rotation_deg"], abs=1e-9)
    assert trans_m * 100 == pytest.approx(rear["recorded_error"]["translation_cm"], abs=1e-9)
    assert sum(1 for s in truth["scans"] if not s["static"]) == 2 * 3


def test_noise_free_scans_lie_on_the_scene(tmp_path: Path) -> None:
    """With zero range noise, true poses put every point exactly on a scene surface."""
    cfg = _small(
        n_stops=3,
        lidars=[
            lidar.model_copy(
                update={"range_noise_m": 0.0, "beams": 16, "horizontal_resolution_deg": 1.0}
            )
            for lidar in rig_preset(16)
        ],
    )
    out = tmp_path / "exact.mcap"
    truth = simulate_calib_session(out, cfg)
    poses = {s["index"]: _matrix(s["world_from_base"]) for s in truth["stops"]}
    mounts = {lidar["topic"]: _matrix(lidar["true_base_from_lidar"]) for lidar in truth["lidars"]}
    stop_of = {(s["topic"], s["stamp_ns"]): s["stop"] for s in truth["scans"]}
    walls = [o for o in truth["scene"]["objects"] if o["type"] == "wall"]
    checked = 0
    for scan in iter_scans(out, list(mounts)):
        world = se3.apply(
            poses[stop_of[(scan.topic, scan.stamp_ns)]] @ mounts[scan.topic], scan.points_m
        )
        # Nothing below the ground; near it, points are on it (up to float32 storage) or on
        # the foot of a vertical face.
        assert world[:, 2].min() > -2e-5
        near = world[:, 2] < 0.05
        assert np.mean(np.abs(world[near, 2]) < 2e-5) > 0.95
        # Points on a wall face: on the plane |n . (p - c)| = thickness / 2.
        for wall in walls:
            yaw = math.radians(wall["yaw_deg"])
            normal_axis = 0 if wall["size_m"][0] < wall["size_m"][1] else 1
            normal = se3.rot_z(yaw)[:, normal_axis]
            offset = np.abs((world - np.array(wall["center_m"])) @ normal)
            on_face = np.abs(offset - wall["size_m"][normal_axis] / 2) < 1e-3
            far = np.abs((world - np.array(wall["center_m"])) @ se3.rot_z(yaw)[:, 1 - normal_axis])
            on_face &= far < wall["size_m"][1 - normal_axis] / 2 - 0.2
            checked += int(on_face.sum())
            assert np.all(np.abs(offset[on_face] - wall["size_m"][normal_axis] / 2) < 1e-4)
    assert checked > 100


def test_same_seed_same_log_other_seed_other_scene(tmp_path: Path) -> None:
    a = simulate_calib_session(tmp_path / "a.mcap", _small(seed=5))
    b = simulate_calib_session(tmp_path / "b.mcap", _small(seed=5))
    c = simulate_calib_session(tmp_path / "c.mcap", _small(seed=6))
    assert a["scene"] == b["scene"] and a["stops"] == b["stops"]
    assert a["scene"] != c["scene"]
    scans_a = list(iter_scans(tmp_path / "a.mcap", ["/lidar/front/points"]))
    scans_b = list(iter_scans(tmp_path / "b.mcap", ["/lidar/front/points"]))
    assert all(
        np.array_equal(x.points_m, y.points_m) for x, y in zip(scans_a, scans_b, strict=True)
    )


def test_other_log_formats_carry_the_same_scans(tmp_path: Path) -> None:
    cfg = _small(n_stops=2)
    simulate_calib_session(tmp_path / "s.mcap", cfg)
    simulate_calib_session(tmp_path / "s.bag", cfg, fmt="bag")
    simulate_calib_session(tmp_path / "s_db3", cfg, fmt="db3")
    ref = list(iter_scans(tmp_path / "s.mcap", ["/lidar/rear/points"]))
    for other in (tmp_path / "s.bag", tmp_path / "s_db3"):
        scans = list(iter_scans(other, ["/lidar/rear/points"]))
        assert [s.stamp_ns for s in scans] == [s.stamp_ns for s in ref]
        assert all(np.array_equal(x.points_m, y.points_m) for x, y in zip(scans, ref, strict=True))
        assert read_static_transforms(other, "/tf_static")


def test_nonsense_scene_configs_are_config_errors() -> None:
    front, rear = rig_preset(32)
    with pytest.raises(ConfigError, match="overlap by"):
        CalibSceneConfig(
            lidars=[front, rear.model_copy(update={"mount_rpy_deg": (0.0, 0.0, 60.0)})]
        )
    with pytest.raises(ConfigError, match="two or more"):
        CalibSceneConfig(lidars=[front])
    with pytest.raises(ConfigError, match="beams"):
        LidarSimConfig(name="x", beams=1)
    with pytest.raises(ConfigError, match="vertical_fov_deg"):
        LidarSimConfig(name="x", vertical_fov_deg=(10.0, -10.0))
    with pytest.raises(ConfigError, match="turning_scans"):
        CalibSceneConfig(turning_scans=2, scans_per_stop=1)
    with pytest.raises(ConfigError, match="n_boxes"):
        SceneConfig(n_boxes=-1)
    message = ""
    try:
        CalibSceneConfig(n_stops=1)
    except ConfigError as exc:
        message = str(exc)
    assert "\n" not in message and "n_stops" in message


def test_drive_session_layouts_tf_chain_and_odometry(tmp_path: Path) -> None:
    """A driving session: organised ouster-ros cloud with zeros, two-level /tf_static,
    odometry on both carriers, stops and moving scans as the config asks."""
    from syncaudit.calib.extrinsics import from_static_transforms
    from syncaudit.calib.io import read_odometry
    from syncaudit.simulate.calib_config import calib_scene_config

    out = tmp_path / "drive.mcap"
    cfg = calib_scene_config(
        motion="drive",
        beams=16,
        n_stops=3,
        organized="second",
        tf_chain="sensor_kit",
        odometry="both",
        mount="bumper_front_rear",
    )
    truth = simulate_calib_session(out, cfg)
    rear = truth["lidars"][1]
    with open_log(out) as log:
        assert log.topics["/odom"].msgtype == "nav_msgs/msg/Odometry"
        assert log.topics["/tf"].msgtype == "tf2_msgs/msg/TFMessage"
        raw = next(iter(log.messages(topics=[rear["topic"]])))
        msg: Any = log.deserialize(raw)
        assert (msg.height, msg.width, msg.point_step) == (16, 600, 48)
        assert not msg.is_dense
        assert [f.name for f in msg.fields][:4] == ["x", "y", "z", "intensity"]
        xyz = np.frombuffer(msg.data, dtype=np.uint8).reshape(16, 600, 48)[:, :, :12]
        no_return = (xyz.view(np.float32).reshape(16, 600, 3) == 0).all(axis=2)
        assert no_return.any() and not no_return.all()  # sky above a low LiDAR: zeros
    decoded = {(s.topic, s.stamp_ns): s.points_m.shape[0] for s in iter_scans(out, [rear["topic"]])}
    for scan in truth["scans"]:
        if scan["topic"] == rear["topic"]:
            assert decoded[(scan["topic"], scan["stamp_ns"])] == scan["points"]
    # Two levels on /tf_static, resolving to the recorded extrinsic exactly.
    edges = read_static_transforms(out, "/tf_static")
    assert {e.parent for e in edges} == {"base_link", "sensor_kit_base_link"}
    resolved = from_static_transforms(edges, [rear["frame_id"]], "test")
    assert resolved.base_frame == "base_link"
    assert np.allclose(
        resolved.base_from_frame[rear["frame_id"]],
        _matrix(rear["recorded_base_from_lidar"]),
        atol=1e-9,
    )
    odometry = read_odometry(out, "base_link")
    assert odometry is not None and odometry.source == "/odom"
    assert odometry.stamps_ns.size == truth["odometry"]["samples"]
    # Every stop holds 3+ static scans per LiDAR; 10-18 sweeps are taken between stops.
    for lidar in truth["lidars"]:
        mine = [s for s in truth["scans"] if s["topic"] == lidar["topic"]]
        for stop in truth["stops"]:
            assert sum(1 for s in mine if s["stop"] == stop["index"]) >= 3
        moving = sum(1 for s in mine if not s["static"])
        assert 2 * 9 <= moving <= 2 * 19
