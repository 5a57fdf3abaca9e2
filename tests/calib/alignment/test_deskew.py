"""Deskewing moving scans (`calib.alignment.deskew`) against the simulator's true motion.

A scan is simulated the way `simulate.calib_session` writes a moving one (each column
fired from the pose at its instant, reported in that instant's sensor frame) at a known
constant body velocity; every point's true world position is known, so the residual of
the deskewed points is measured against the truth, before and after.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import NDArray

from syncaudit.calib import se3
from syncaudit.calib.alignment import deskew
from syncaudit.simulate.calib_config import SceneConfig, rig_preset
from syncaudit.simulate.scene import beam_pattern, build_scene, simulate_scan

F64 = NDArray[np.float64]
_PERIOD_NS = 100_000_000
_VELOCITY = np.array([0.0, 0.0, math.radians(40.0), 2.0, 0.3, 0.0])
"""Body velocity of the sensor: 40 deg/s yaw, 2 m/s forward, 0.3 m/s sideways (a turn
out of a stop at the simulator's peak speed)."""


def _pose(dt_s: F64) -> F64:
    """world_from_sensor at `dt_s` from the sweep's middle instant (sensor at the origin
    then, 1.9 m up), at the constant body velocity."""
    rot, trans = deskew.motion_at(_VELOCITY, dt_s)
    out = np.zeros((dt_s.size, 4, 4))
    out[:, :3, :3], out[:, :3, 3], out[:, 3, 3] = rot, trans, 1.0
    mid = se3.make_transform(np.eye(3), (0.0, 0.0, 1.9))
    return np.asarray(mid[None] @ out)


def _moving_scan(*, backwards: bool = False, fov_deg: float = 120.0) -> tuple[F64, F64, F64]:
    """(points in each instant's sensor frame, time of each point from the sweep start in
    ns, true world points): one sweep of `fov_deg` (the rig's 120 deg: 33 ms)."""
    lidar = rig_preset(32)[0].model_copy(update={"horizontal_fov_deg": fov_deg})
    pattern = beam_pattern(lidar)
    scene = build_scene(SceneConfig(), np.random.default_rng([7, 0]))
    sweep_s = _PERIOD_NS * 1e-9 * lidar.horizontal_fov_deg / 360.0
    order = np.arange(pattern.n_columns)
    if backwards:
        order = order[::-1]  # the other spin direction: the last column fires first
    col_time_s = (order + 0.5) / pattern.n_columns * sweep_s
    poses = _pose(col_time_s - sweep_s / 2.0)
    scan = simulate_scan(scene, lidar, pattern, poses, np.random.default_rng([7, 2]))
    times_ns = col_time_s[scan.column] * 1e9
    per_point = poses[scan.column]
    points = scan.points_m.astype(np.float64)
    world = np.einsum("nij,nj->ni", per_point[:, :3, :3], points) + per_point[:, :3, 3]
    return points, times_ns, world


def _residual_m(points_at_middle: F64, world: F64) -> F64:
    """Distance of each point, placed from the middle instant's pose, to its true place."""
    return np.asarray(
        np.linalg.norm(se3.apply(_pose(np.zeros(1))[0], points_at_middle) - world, axis=1)
    )


def test_body_velocity_and_motion_at_are_inverse() -> None:
    """The constant velocity that moves by T in 1 s, integrated for 1 s, is T again."""
    target = se3.make_transform(se3.rpy_to_matrix(0.05, -0.1, 1.2), (1.5, -0.4, 0.2))
    velocity = deskew.body_velocity(target, 0.5)
    rot, trans = deskew.motion_at(velocity, np.array([0.5]))
    assert np.allclose(rot[0], target[:3, :3], atol=1e-12)
    assert np.allclose(trans[0], target[:3, 3], atol=1e-12)


@pytest.mark.parametrize(("backwards", "fov_deg"), [(False, 120.0), (True, 120.0), (False, 360.0)])
def test_deskew_with_the_true_motion_lands_on_the_static_scene(
    backwards: bool, fov_deg: float
) -> None:
    """Raw, the moving scan's points sit centimetres off the scene (120 deg sweep: the
    sensor turned 1.3 deg and moved 7 cm meanwhile; 360 deg: 4 deg, 20 cm); deskewed with
    the true motion by the per-azimuth time table, within a millimetre (measured: median
    0.18 mm, 95th percentile 0.56 mm for 120 deg; the 1 cm range noise does not enter,
    the truth being each ray's own hit). On a full turn the seam's bins, where the first
    and last columns meet, are dropped."""
    points, times_ns, world = _moving_scan(backwards=backwards, fov_deg=fov_deg)
    sweep = deskew.sweep_times(points, times_ns)
    assert deskew.refusal(sweep, _PERIOD_NS) is None
    before = _residual_m(points, world)
    after, middle_ns = deskew.deskew_scan(points, sweep, _VELOCITY)
    kept = np.isfinite(deskew.point_times_ns(sweep, points))
    after_res = _residual_m(after, world[kept])
    assert abs(middle_ns - 0.5 * (times_ns.min() + times_ns.max())) < 1.0
    assert kept.mean() > 0.99  # only the seam's bins are dropped
    assert np.median(before) > 0.03 and np.percentile(before, 95) > 0.1
    assert np.median(after_res) < 0.001 and np.percentile(after_res, 95) < 0.002


def test_wrong_motion_sign_makes_it_worse() -> None:
    """The sign matters: deskewing with the reversed motion doubles the distortion."""
    points, times_ns, world = _moving_scan()
    sweep = deskew.sweep_times(points, times_ns)
    before = float(np.median(_residual_m(points, world)))
    wrong, _ = deskew.deskew_scan(points, sweep, -_VELOCITY)
    kept = np.isfinite(deskew.point_times_ns(sweep, points))
    assert float(np.median(_residual_m(wrong, world[kept]))) > 1.8 * before


def test_stamp_at_the_sweep_end_or_absolute_times_give_the_same_points() -> None:
    """Drivers differ in what the header stamp marks (ROS 1 velodyne: the last packet, so
    times <= 0; ouster/nebula: the first point). The absolute instants are the same, so
    the deskewed scan and its instant (stamp + middle) are too."""
    points, times_ns, _world = _moving_scan()
    stamp_ns = 1_700_000_000_000_000_000
    span = float(times_ns.max())
    start = deskew.sweep_times(points, times_ns)
    end = deskew.sweep_times(points, times_ns - span)
    a, mid_a = deskew.deskew_scan(points, start, _VELOCITY)
    b, mid_b = deskew.deskew_scan(points, end, _VELOCITY)
    assert end.last_ns <= 0.0
    assert np.allclose(a, b, atol=1e-6)
    assert abs((stamp_ns + mid_a) - (stamp_ns + span + mid_b)) < 1.0


def test_unusable_times_are_refused_with_a_reason() -> None:
    """No time field, all-equal times, times restarting per 1.3 ms packet, times spanning
    several scans, and times that are not a function of azimuth are refused."""
    points, times_ns, _world = _moving_scan()
    assert "no per-point time" in str(deskew.refusal(None, _PERIOD_NS))
    zero = deskew.sweep_times(points, np.zeros_like(times_ns))
    assert "span 0.00 ms" in str(deskew.refusal(zero, _PERIOD_NS))
    per_packet = deskew.sweep_times(points, times_ns % 1_300_000.0)
    assert "restarting per packet" in str(deskew.refusal(per_packet, _PERIOD_NS))
    long = deskew.sweep_times(points, times_ns * 6.0)
    assert "over 1.5 scan periods" in str(deskew.refusal(long, _PERIOD_NS))
    shuffled = deskew.sweep_times(points, np.random.default_rng(3).permutation(times_ns))
    assert "not a function of azimuth" in str(deskew.refusal(shuffled, _PERIOD_NS))
