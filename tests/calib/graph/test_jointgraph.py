"""The joint graph (calib.jointgraph) on hand-made hand-eye problems with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from syncaudit.calib import se3
from syncaudit.calib.graph.jointgraph import Ground, Link, Problem, free_directions, solve
from syncaudit.calib.refinement.joint_estimate import pinned_by_grounds
from syncaudit.calib.settings import CalibConfig, PoseGraphConfig

pytest.importorskip("gtsam")

TRUE_EXT = se3.make_transform(se3.rpy_to_matrix(0.01, -0.02, math.pi - 0.05), (-2.8, 0.1, -0.1))
"""reference_from_rear: a rear LiDAR 2.8 m behind, turned round, slightly tilted."""


def _vehicle(n: int) -> dict[int, np.ndarray]:
    """Planar reference-LiDAR poses of a vehicle turning 30-40 deg and moving 0.5-1 m per stop."""
    rng = np.random.default_rng(3)
    poses, x, y, yaw = {}, 0.0, 0.0, 0.0
    for k in range(n):
        poses[k] = se3.make_transform(se3.rot_z(yaw), (x, y, 0.0))
        step, turn = rng.uniform(0.5, 1.0), math.radians(rng.uniform(30, 40))
        x, y, yaw = x + step * math.cos(yaw), y + step * math.sin(yaw), yaw + turn
    return poses


def _links(poses: dict[int, np.ndarray], lidar: int, pairs: list[tuple[int, int]]) -> list[Link]:
    ext = TRUE_EXT if lidar else np.eye(4)
    info = np.diag([1e10, 1e10, 1e10, 1e9, 1e9, 1e9])  # 0.0006 deg, 0.003 cm
    return [
        Link(
            lidar,
            a,
            lidar,
            b,
            se3.invert(ext) @ se3.invert(poses[a]) @ poses[b] @ ext,
            info,
            "scan",
        )
        for a, b in pairs
    ]


def _problem(grounds: list[Ground], *, shared: bool = True) -> Problem:
    """Stops 0-1 seen by the reference only, 6-7 by the rear only, 2-5 by both (three
    motions both see: the hand-eye constraint); without `shared` both see only 3-4."""
    poses = _vehicle(8)
    ref = (
        [(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (2, 4)]
        if shared
        else [(0, 1), (1, 2), (2, 3), (3, 4)]
    )
    rear = (
        [(2, 3), (3, 4), (4, 5), (5, 6), (6, 7), (3, 5)]
        if shared
        else [(3, 4), (4, 5), (5, 6), (6, 7)]
    )
    links = _links(poses, 0, ref) + _links(poses, 1, rear)
    seed = TRUE_EXT @ se3.make_transform(se3.rot_z(0.02), (0.05, -0.04, 0.03))
    initial = {
        k: p @ se3.make_transform(se3.rot_z(0.01), (0.02, 0.0, 0.0)) for k, p in poses.items()
    }
    initial[0] = poses[0]
    return Problem(0, initial, {1: seed}, links, grounds, up=np.array([0.0, 0.0, 1.0]))


def test_hand_eye_recovers_the_extrinsic_but_its_height_without_ground() -> None:
    solution = solve(_problem([]), PoseGraphConfig())
    rot_deg, _trans_m = se3.transform_difference(TRUE_EXT, solution.extrinsics[1])
    assert rot_deg < 0.01
    # Planar motion cannot see the height: the seed's 3 cm stays, and the graph says so.
    diff = se3.invert(TRUE_EXT) @ solution.extrinsics[1]
    assert abs(abs(diff[2, 3]) - 0.03) < 0.005
    assert math.hypot(diff[0, 3], diff[1, 3]) < 0.002
    free = free_directions(solution.covariances[1], 0.1, 1.0)
    assert [kind for kind, _axis, _sigma in free] == ["translation"]
    axis = np.array(free[0][1])
    assert abs(float(axis @ (TRUE_EXT[:3, :3].T @ np.array([0.0, 0.0, 1.0])))) > 0.99


def _grounds() -> list[Ground]:
    """Ground 1.9 m below the reference: n.p + d = 0 with n up, d = 1.9; the rear's is the
    same plane in its own frame."""
    up_rear = TRUE_EXT[:3, :3].T @ np.array([0.0, 0.0, 1.0])
    offset_rear = 1.9 + float(np.array([0.0, 0.0, 1.0]) @ TRUE_EXT[:3, 3])
    return [
        Ground(0, np.array([0.0, 0.0, 1.0]), 1.9, 0.05, 0.002),
        Ground(1, up_rear, offset_rear, 0.05, 0.002),
    ]


def test_ground_planes_fix_the_height() -> None:
    solution = solve(_problem(_grounds()), PoseGraphConfig())
    rot_deg, trans_m = se3.transform_difference(TRUE_EXT, solution.extrinsics[1])
    assert rot_deg < 0.01 and trans_m < 0.002
    assert free_directions(solution.covariances[1], 0.1, 1.0) == []
    assert max(r.sigmas for r in solution.residuals) < 0.1


def test_one_motion_seen_by_both_leaves_the_yaw_free_and_says_so() -> None:
    """Stops 5-7 seen by the rear only, with no odometry, move with any extrinsic: only
    the 3-4 motion ties the LiDARs, and one motion cannot fix the turn about its axis."""
    solution = solve(_problem([], shared=False), PoseGraphConfig())
    kinds = [kind for kind, _axis, _sigma in free_directions(solution.covariances[1], 0.1, 1.0)]
    assert "rotation" in kinds


def test_ground_planes_come_back_where_the_graph_leaves_the_height_free() -> None:
    """The final solve leaves the ground planes out where the turn axis is the up; where
    the graph then cannot see the height, they come back (not the map-to-map refinement)."""
    problem = _problem([])
    loose = solve(problem, PoseGraphConfig())
    grounds = _grounds()
    pinned, used = pinned_by_grounds(problem, loose, grounds, CalibConfig())
    assert used is grounds
    diff = se3.invert(TRUE_EXT) @ pinned.extrinsics[1]
    assert abs(diff[2, 3]) < 0.002  # the seed's 3 cm gone
    assert free_directions(pinned.covariances[1], 0.25, 2.0) == []
    # A graph that holds them already is left as it was.
    held = _problem(grounds)
    solution = solve(held, PoseGraphConfig())
    again, used = pinned_by_grounds(held, solution, _grounds(), CalibConfig())
    assert again is solution and used is held.grounds
