"""The simulator's own geometry (`simulate.rigid`) against numbers written by hand.

The same numbers pin `calib.se3` in tests/calib/test_se3_conventions.py: the simulator
writes `/tf_static` with this code and the calibrator reads it with that one, so each is
held to the conventions on its own, and a mistake in one cannot cancel out in the other.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from syncaudit.logs import open_log
from syncaudit.simulate import rigid
from syncaudit.simulate.calib_config import CalibSceneConfig, LidarSimConfig
from syncaudit.simulate.calib_session import simulate_calib_session

H = math.sqrt(0.5)
YAW_90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def test_yaw_90_deg_is_the_quaternion_0_0_h_h() -> None:
    assert np.allclose(rigid.rpy_matrix(0.0, 0.0, math.pi / 2), YAW_90, atol=1e-15)
    assert np.allclose(rigid.yaw_matrix(math.pi / 2), YAW_90, atol=1e-15)
    assert rigid.quaternion_xyzw(YAW_90) == pytest.approx((0.0, 0.0, H, H), abs=1e-15)
    assert rigid.quaternion_xyzw(YAW_90.T) == pytest.approx((0.0, 0.0, -H, H), abs=1e-15)
    # 180 deg about x (trace -1): the largest component is x, w is 0.
    flip = np.diag([1.0, -1.0, -1.0])
    assert rigid.quaternion_xyzw(flip) == pytest.approx((1.0, 0.0, 0.0, 0.0), abs=1e-15)


def test_parent_from_child_maps_the_childs_points_into_the_parent() -> None:
    """A child 1 m ahead on x, yawed 90 deg: its point (1, 0, 0) is the parent's (1, 1, 0)."""
    parent_from_child = rigid.transform(YAW_90, (1.0, 0.0, 0.0))
    point = parent_from_child @ np.array([1.0, 0.0, 0.0, 1.0])
    assert point[:3] == pytest.approx([1.0, 1.0, 0.0], abs=1e-15)
    assert rigid.inverse(parent_from_child)[:3, 3] == pytest.approx([0.0, 1.0, 0.0], abs=1e-15)


def test_roll_and_pitch_signs() -> None:
    """Positive roll turns +y to +z; positive pitch turns +x to -z (nose down), as in ROS."""
    roll = rigid.rpy_matrix(math.pi / 2, 0.0, 0.0)
    assert roll @ np.array([0.0, 1.0, 0.0]) == pytest.approx([0.0, 0.0, 1.0], abs=1e-15)
    assert rigid.quaternion_xyzw(roll) == pytest.approx((H, 0.0, 0.0, H), abs=1e-15)
    pitch = rigid.rpy_matrix(0.0, math.pi / 2, 0.0)
    assert pitch @ np.array([1.0, 0.0, 0.0]) == pytest.approx([0.0, 0.0, -1.0], abs=1e-15)
    assert rigid.quaternion_xyzw(pitch) == pytest.approx((0.0, H, 0.0, H), abs=1e-15)
    small = rigid.rpy_matrix(math.radians(2.0), math.radians(-3.0), math.radians(5.0))
    assert [math.degrees(v) for v in rigid.rpy_of(small)] == pytest.approx(
        [2.0, -3.0, 5.0], abs=1e-12
    )


def test_roll_is_applied_before_yaw_about_the_fixed_axes() -> None:
    """rpy (90, 0, 90) deg = Rz(90) Rx(90): x -> y, y -> z, z -> x, the quaternion (.5, .5, .5, .5)."""
    rot = rigid.rpy_matrix(math.pi / 2, 0.0, math.pi / 2)
    expected = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    assert np.allclose(rot, expected, atol=1e-15)
    assert rigid.quaternion_xyzw(rot) == pytest.approx((0.5, 0.5, 0.5, 0.5), abs=1e-15)


def test_transforms_compose_parent_first_and_differences_are_exact() -> None:
    world_from_parent = rigid.transform(YAW_90, (1.0, 0.0, 0.0))
    world_from_child = world_from_parent @ rigid.transform(np.eye(3), (1.0, 0.0, 0.0))
    assert world_from_child[:3, 3] == pytest.approx([1.0, 1.0, 0.0], abs=1e-15)
    assert rigid.difference(world_from_parent, world_from_child) == pytest.approx(
        (0.0, 1.0), abs=1e-12
    )
    tilted = rigid.transform(rigid.axis_angle_matrix(np.array([0.0, 0.0, math.pi / 2])), (0, 0, 0))
    assert np.allclose(tilted[:3, :3], YAW_90, atol=1e-15)
    assert rigid.difference(np.eye(4), tilted)[0] == pytest.approx(90.0, abs=1e-12)


def _raw_tf(log: Path) -> dict[str, Any]:
    """child frame -> (parent, translation, quaternion) as the simulated log holds them."""
    out = {}
    with open_log(log) as reader:
        for raw in reader.messages(topics=["/tf_static"]):
            msg: Any = reader.deserialize(raw)
            for tr in msg.transforms:
                t, q = tr.transform.translation, tr.transform.rotation
                out[tr.child_frame_id] = (tr.header.frame_id, (t.x, t.y, t.z), (q.x, q.y, q.z, q.w))
    return out


def test_the_simulated_tf_static_holds_the_mount_as_written_by_hand(tmp_path: Path) -> None:
    """A LiDAR mounted 1 m ahead and yawed 90 deg is on /tf_static as translation (1, 0, 0)
    and quaternion (0, 0, sqrt(1/2), sqrt(1/2)), parent base_link."""
    small: dict[str, Any] = {"beams": 4, "horizontal_resolution_deg": 5.0}
    lidars = [
        LidarSimConfig(name="left", mount_xyz_m=(1.0, 0.0, 0.0), mount_rpy_deg=(0, 0, 90), **small),
        LidarSimConfig(name="right", mount_xyz_m=(0, 0, 1.5), mount_rpy_deg=(0, 0, -90), **small),
    ]
    log = tmp_path / "s.mcap"
    truth = simulate_calib_session(log, CalibSceneConfig(n_stops=2, lidars=lidars))
    tf = _raw_tf(log)
    parent, xyz, quat = tf["lidar_left"]
    assert parent == "base_link"
    assert xyz == pytest.approx((1.0, 0.0, 0.0), abs=1e-12)
    assert quat == pytest.approx((0.0, 0.0, H, H), abs=1e-12)
    assert tf["lidar_right"][2] == pytest.approx((0.0, 0.0, -H, H), abs=1e-12)
    true = truth["lidars"][0]["true_base_from_lidar"]
    assert true["rpy_deg"] == pytest.approx([0.0, 0.0, 90.0], abs=1e-12)
    # The right LiDAR seen from the left one: 180 deg about z, 1 m to its left (+y), 1.5 m up.
    rel = truth["lidars"][1]["true_left_from_lidar"]
    assert rel["translation_m"] == pytest.approx([0.0, 1.0, 1.5], abs=1e-12)
    assert [abs(v) for v in rel["quaternion_xyzw"]] == pytest.approx([0, 0, 1, 0], abs=1e-12)
