"""Where a moving scan belongs in time (`moving_scans._place`): still at another LiDAR's
stop, or between two placed stops with a seed pose and a motion.

Built from bare scan times (no point clouds): LiDAR "a" has still runs at stops 0 and 1;
LiDAR "b" has a run at stop 0 only, and at stop 1 a run that never ends (it faces bare
ground, so it looks still while the vehicle drives on).
"""

from __future__ import annotations

import math

import numpy as np

from syncaudit.calib import extrinsics as extr
from syncaudit.calib import se3
from syncaudit.calib.alignment import deskew, moving_scans
from syncaudit.calib.graph import jointgraph
from syncaudit.calib.selection.stop_choice import Run, VehicleStop
from syncaudit.calib.settings import CalibConfig
from syncaudit.calib.state import LidarState, SampledScan

_MS = 1_000_000
_SWEEP = deskew.SweepTimes(
    times_ns=np.zeros(720, dtype=np.float32), first_ns=0.0, last_ns=33 * _MS, known_share=1.0
)


def _lidar(topic: str, starts_ms: list[int]) -> LidarState:
    scans = [SampledScan(t * _MS, np.zeros((1, 3), np.float32), _SWEEP) for t in starts_ms]
    return LidarState(topic=topic, frame_id=topic, scans=scans, up=np.array([0.0, 0.0, 1.0]))


def _stops() -> list[VehicleStop]:
    stops = [
        VehicleStop(0, 0, 450 * _MS, {"a": Run("a", (0, 1, 2), 0, 200 * _MS)}),
        VehicleStop(1, 1500 * _MS, 2050 * _MS, {"a": Run("a", (5, 6), 1500 * _MS, 1600 * _MS)}),
    ]
    stops[0].runs["b"] = Run("b", (0, 1), 50 * _MS, 150 * _MS)
    stops[1].runs["b"] = Run("b", tuple(range(5, 11)), 1550 * _MS, 2050 * _MS)
    return stops


def _stage() -> tuple[moving_scans._Stage, list[LidarState]]:
    a = _lidar("a", [0, 100, 200, 300, 400, 1500, 1600, 1700, 1800])
    b = _lidar("b", [50, 150, 250, 350, 450, 1550, 1650, 1750, 1850, 1950, 2050])
    stops = _stops()
    x1 = se3.make_transform(se3.rot_z(math.radians(30.0)), (1.0, 0.5, 0.0))
    solution = jointgraph.JointSolution(
        poses={0: np.eye(4), 1: x1},
        extrinsics={1: np.eye(4)},
        covariances={1: np.eye(6)},
        residuals=[],
        error_before=0.0,
        error_after=0.0,
        iterations=0,
    )
    recorded = extr.RecordedExtrinsics("test", "base", {"a": np.eye(4), "b": np.eye(4)})
    stage = moving_scans._Stage([a, b], stops, recorded, None, CalibConfig(), solution)
    return stage, [a, b]


def _candidate(stage: moving_scans._Stage, lidar: int, index: int) -> moving_scans._Candidate:
    scan = stage.lidars[lidar].scans[index]
    sweep = moving_scans._scan_interval(scan)
    cand = moving_scans._Candidate(lidar, index, sweep, 0.5 * (sweep.start_ns + sweep.end_ns), -1)
    moving_scans._place(stage, cand, stage.lidars[lidar].topic)
    return cand


def test_a_scan_inside_another_lidars_still_run_shares_that_stop() -> None:
    """A scan of LiDAR b inside a's still run at a stop b has no run of: that stop's pose;
    one that ends after the stop's window (b at 250-283 ms, stop 0's window 50-183 ms) and
    a's scan at 300 ms are moving, between stops 0 and 1."""
    stage, lidars = _stage()
    # Stop 2: only a stood (b's run detection found nothing), 2500-2633 ms.
    lidars[0].scans += [
        SampledScan(t * _MS, np.zeros((1, 3), np.float32), _SWEEP) for t in (2500, 2600)
    ]
    lidars[1].scans.append(SampledScan(2550 * _MS, np.zeros((1, 3), np.float32), _SWEEP))
    stop2 = VehicleStop(2, 2500 * _MS, 2600 * _MS, {"a": Run("a", (9, 10), 2500 * _MS, 2600 * _MS)})
    poses = {**stage.poses, 2: se3.make_transform(np.eye(3), (2.0, 0.0, 0.0))}
    solution = jointgraph.JointSolution(poses, {1: np.eye(4)}, {1: np.eye(6)}, [], 0.0, 0.0, 0)
    stops = [*_stops(), stop2]
    stage = moving_scans._Stage(lidars, stops, stage.recorded, None, CalibConfig(), solution)
    still = _candidate(stage, 1, 11)  # b at 2550-2583 ms
    assert still.still_at == 2 and still.key == 2 and still.reason is None
    assert still.seed is not None and np.allclose(still.seed, poses[2])
    assert still.velocity is not None and not still.velocity.any()
    assert stage.windows[0] == moving_scans.Interval(50 * _MS, 183 * _MS)  # b's, the shorter
    late = _candidate(stage, 1, 2)  # b at 250-283 ms: after a's still run ended (233 ms)
    assert late.still_at is None and (late.before, late.after) == (0, 1)
    a_scan = _candidate(stage, 0, 3)  # a at 300 ms: moving between the stops
    assert a_scan.still_at is None and (a_scan.before, a_scan.after) == (0, 1)


def test_a_ground_facing_lidars_endless_run_does_not_stretch_the_stop() -> None:
    """Stop 1's window is a's short run (1500-1633 ms), not b's 1550-2083 ms one: a's scan
    at 1800 ms is not taken as still there (it is after the last placed stop)."""
    stage, _ = _stage()
    assert stage.windows[1] == moving_scans.Interval(1500 * _MS, 1633 * _MS)
    after = _candidate(stage, 0, 8)
    assert after.still_at is None and after.reason == "not between two placed stops"


def test_a_scan_at_a_stop_this_lidar_has_still_scans_of_is_not_reused() -> None:
    stage, _ = _stage()
    own = _candidate(stage, 0, 1)  # a at 100-133 ms: inside stop 0, where a has a run
    assert own.reason == "at a stop this LiDAR has still scans of"
    edge = _candidate(stage, 1, 6)  # b at 1650 ms: past stop 1's window, none after it
    assert edge.still_at is None and edge.reason == "not between two placed stops"


def test_the_seed_is_interpolated_between_the_stops_and_the_motion_spans_the_gap() -> None:
    """Without odometry: the seed pose a share s of the way from X_0 to X_1 (constant
    velocity over the gap from stop 0's end to stop 1's start), and the body velocity
    that covers the stop-to-stop motion in that gap."""
    stage, _ = _stage()
    cand = _candidate(stage, 0, 3)  # a at 300-333 ms, mid 316.5 ms
    gap_s = (1500 - 183) * 1e-3
    share = (316.5 - 183) / (1500 - 183)
    assert cand.seed is not None and cand.velocity is not None
    yaw = math.degrees(math.atan2(cand.seed[1, 0], cand.seed[0, 0]))
    assert abs(yaw - 30.0 * share) < 1e-6
    rot, trans = deskew.motion_at(cand.velocity, np.array([gap_s]))
    assert np.allclose(se3.make_transform(rot[0], trans[0]), stage.poses[1], atol=1e-9)
