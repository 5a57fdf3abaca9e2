"""`calib.se3` against numbers written by hand, not round trips of itself.

A round trip (matrix -> quaternion -> matrix) passes with x and w swapped or a transform
taken the wrong way; these do not. The same numbers pin the simulator's own geometry in
tests/simulate/test_rigid.py, so the two cannot agree on a mistake.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from syncaudit.calib import se3
from syncaudit.calib.io import read_static_transforms
from syncaudit.writers.log_writer import open_writer

H = math.sqrt(0.5)
YAW_90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def test_yaw_90_deg_is_the_quaternion_0_0_h_h() -> None:
    assert np.allclose(se3.rpy_to_matrix(0.0, 0.0, math.pi / 2), YAW_90, atol=1e-15)
    assert se3.matrix_to_quaternion(YAW_90) == pytest.approx((0.0, 0.0, H, H), abs=1e-15)
    assert np.allclose(se3.quaternion_to_matrix(0.0, 0.0, H, H), YAW_90, atol=1e-15)
    # Yaw -90 deg: w stays positive, z goes negative.
    assert se3.matrix_to_quaternion(YAW_90.T) == pytest.approx((0.0, 0.0, -H, H), abs=1e-15)


def test_parent_from_child_maps_the_childs_points_into_the_parent() -> None:
    """A child 1 m ahead on x, yawed 90 deg: its point (1, 0, 0) is the parent's (1, 1, 0)."""
    parent_from_child = se3.make_transform(YAW_90, (1.0, 0.0, 0.0))
    point = se3.apply(parent_from_child, np.array([[1.0, 0.0, 0.0]]))
    assert point[0] == pytest.approx([1.0, 1.0, 0.0], abs=1e-15)
    # The other way: the parent's origin seen from the child is 1 m to its left (+y).
    child_from_parent = se3.invert(parent_from_child)
    assert child_from_parent[:3, 3] == pytest.approx([0.0, 1.0, 0.0], abs=1e-15)


def test_roll_and_pitch_signs() -> None:
    """Positive roll turns +y to +z; positive pitch turns +x to -z (nose down), as in ROS."""
    roll = se3.rpy_to_matrix(math.pi / 2, 0.0, 0.0)
    assert roll @ np.array([0.0, 1.0, 0.0]) == pytest.approx([0.0, 0.0, 1.0], abs=1e-15)
    assert se3.matrix_to_quaternion(roll) == pytest.approx((H, 0.0, 0.0, H), abs=1e-15)
    pitch = se3.rpy_to_matrix(0.0, math.pi / 2, 0.0)
    assert pitch @ np.array([1.0, 0.0, 0.0]) == pytest.approx([0.0, 0.0, -1.0], abs=1e-15)
    assert se3.matrix_to_quaternion(pitch) == pytest.approx((0.0, H, 0.0, H), abs=1e-15)
    small = se3.rpy_to_matrix(math.radians(2.0), math.radians(-3.0), math.radians(5.0))
    roll_rad, pitch_rad, yaw_rad = se3.matrix_to_rpy(small)
    assert math.degrees(roll_rad) == pytest.approx(2.0, abs=1e-12)
    assert math.degrees(pitch_rad) == pytest.approx(-3.0, abs=1e-12)
    assert math.degrees(yaw_rad) == pytest.approx(5.0, abs=1e-12)


def test_roll_is_applied_before_yaw_about_the_fixed_axes() -> None:
    """rpy (90, 0, 90) deg = Rz(90) Rx(90): x -> y, y -> z, z -> x, the quaternion (.5, .5, .5, .5)."""
    rot = se3.rpy_to_matrix(math.pi / 2, 0.0, math.pi / 2)
    expected = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    assert np.allclose(rot, expected, atol=1e-15)
    assert se3.matrix_to_quaternion(rot) == pytest.approx((0.5, 0.5, 0.5, 0.5), abs=1e-15)


def test_transforms_compose_parent_first() -> None:
    """world_from_child = world_from_parent @ parent_from_child."""
    world_from_parent = se3.make_transform(YAW_90, (1.0, 0.0, 0.0))
    parent_from_child = se3.make_transform(np.eye(3), (1.0, 0.0, 0.0))
    world_from_child = world_from_parent @ parent_from_child
    assert world_from_child[:3, 3] == pytest.approx([1.0, 1.0, 0.0], abs=1e-15)
    assert se3.transform_difference(world_from_parent, world_from_child) == pytest.approx(
        (0.0, 1.0), abs=1e-12
    )


def test_exp_so3_turns_counter_clockwise_about_its_axis() -> None:
    rot = se3.exp_so3(np.array([0.0, 0.0, math.pi / 2]))
    assert np.allclose(rot, YAW_90, atol=1e-15)
    assert se3.rotation_angle_deg(rot) == pytest.approx(90.0, abs=1e-12)


def test_a_tf_static_transform_reads_as_parent_from_child(tmp_path: Path) -> None:
    """base_link -> lidar 1 m ahead, yawed 90 deg, written by hand: the lidar's (1, 0, 0)
    is base_link's (1, 1, 0)."""
    log = tmp_path / "tf.mcap"
    with open_writer(log, "mcap") as writer:
        writer.add_topic("/tf_static", "tf2_msgs/msg/TFMessage", latched=True)
        transform = writer.new_msg(
            "geometry_msgs/msg/TransformStamped",
            header=writer.header(1_000, "base_link"),
            child_frame_id="lidar",
            transform=writer.new_msg(
                "geometry_msgs/msg/Transform",
                translation=writer.new_msg("geometry_msgs/msg/Vector3", x=1.0, y=0.0, z=0.0),
                rotation=writer.new_msg("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=H, w=H),
            ),
        )
        writer.write_msg(
            "/tf_static", 1_000, writer.new_msg("tf2_msgs/msg/TFMessage", transforms=[transform])
        )
    (edge,) = read_static_transforms(log, "/tf_static")
    assert (edge.parent, edge.child) == ("base_link", "lidar")
    point = se3.apply(edge.parent_from_child, np.array([[1.0, 0.0, 0.0]]))
    assert point[0] == pytest.approx([1.0, 1.0, 0.0], abs=1e-15)
