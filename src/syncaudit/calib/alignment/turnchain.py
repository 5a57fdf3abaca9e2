"""The turn chain: the vehicle's coarse motion between stops, hence seeds and stop angles."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib import extrinsics as extr
from syncaudit.calib import io, se3
from syncaudit.calib.alignment.ground import remove_ground
from syncaudit.calib.alignment.registration import Cloud, evaluate, gicp, prepare, yaw_search
from syncaudit.calib.selection import stop_choice
from syncaudit.calib.settings import CalibConfig
from syncaudit.calib.state import LidarState, vehicle_points

F64 = NDArray[np.float64]


_MIN_STRUCTURE_OVERLAP = 0.3
_MAX_STRUCTURE_RMSE_FACTOR = 0.5
_TURN_LOOKBACK = 3
_MAX_TURN_TILT_DEG = 10.0
"""A coarse vehicle motion between stops that tilts the base more than this is no drive
on level ground (the planar model): measured on a diagonal-mount drive, a 28 deg turn
came out upside down (tilt 179 deg, 3.84 m up), verified on structure alone, and every
later stop's angle was wrong (none used). Height is not checked: correct coarse motions
(0.5 m voxels, ground removed) were measured up to 55 cm off in height."""


def verify_turn(
    full: tuple[Cloud, Cloud], structure: tuple[Cloud, Cloud], turn: F64, config: CalibConfig
) -> str | None:
    """Second criterion for a turn hypothesis (None: verified): the structure off the
    ground must overlap and lie on itself within half a coarse voxel, and the full clouds
    must constrain every direction."""
    reg = config.registration
    if config.pose_graph.motion == "planar":
        tilt_deg = math.degrees(math.acos(min(1.0, max(-1.0, float(turn[2, 2])))))
        if tilt_deg > _MAX_TURN_TILT_DEG:
            return f"not a motion on level ground (the base tilts {tilt_deg:.1f} deg)"
    fit = evaluate(structure[0], structure[1], turn, reg.coarse_voxel_m, reg.num_threads)
    if fit.overlap < _MIN_STRUCTURE_OVERLAP:
        return f"structure off the ground overlaps {fit.overlap:.0%} < {_MIN_STRUCTURE_OVERLAP:.0%}"
    if fit.rmse_m > _MAX_STRUCTURE_RMSE_FACTOR * reg.coarse_voxel_m:
        return f"structure off the ground misfits by {fit.rmse_m * 100:.0f} cm"
    up = np.array([0.0, 0.0, 1.0])
    cond = evaluate(full[0], full[1], turn, reg.coarse_voxel_m, reg.num_threads, up).conditioning
    if (
        cond.translation_information < reg.turn_min_translation_information
        or cond.rotation_information < reg.turn_min_rotation_information
    ):
        return f"degenerate view ({cond.describe()})"
    return None


def _find_turn(
    a: int,
    b: int,
    full: dict[int, Cloud],
    structure: dict[int, Cloud],
    prior: F64 | None,
    config: CalibConfig,
) -> tuple[F64 | None, str]:
    """The vehicle's motion `a_from_b` (base frame), or None and why not.

    With odometry, GICP on the structure starts from its motion and the search is not
    needed when that verifies; otherwise yaw hypotheses are scored on the structure off
    the ground (ground removed), and the winner must pass `verify_turn`.
    """
    reg = config.registration
    pair = (structure[a], structure[b])
    why = "no yaw hypothesis verified"
    if prior is not None:
        result = gicp(pair[0], pair[1], prior, reg.coarse_max_correspondence_m, reg.num_threads, 30)
        turn = np.asarray(result.T_target_source, dtype=np.float64)
        why = verify_turn((full[a], full[b]), pair, turn, config) or ""
        if not why:
            return turn, ""
        why = f"from odometry: {why}"
    _yaw, found = yaw_search(
        [(pair[0], pair[1], np.eye(4))],
        step_deg=reg.yaw_search_step_deg,
        max_step_deg=reg.max_step_deg,
        max_correspondence_m=reg.coarse_max_correspondence_m,
        overlap_distance_m=reg.coarse_voxel_m,
        threads=reg.num_threads,
    )
    turn = found[0][0]
    problem = verify_turn((full[a], full[b]), pair, turn, config)
    if problem is None:
        return turn, ""
    return None, problem if prior is None else f"{why}; search: {problem}"


def angular_chain(
    lidars: list[LidarState],
    recorded: extr.RecordedExtrinsics,
    reference: int,
    config: CalibConfig,
    odometry: io.Odometry | None,
    notes: list[str],
) -> int:
    """Coarse vehicle motion between stops, hence each LiDAR's seeds and stop angles.

    The motion is unknown but common to every LiDAR, so it is estimated once from all
    LiDARs' scans merged in the base frame (through the recorded extrinsics). Each stop is
    linked to the nearest earlier stop (up to three back) whose motion verifies, so one
    weak link does not cut the stops after it; stops that link to nothing start a new
    segment, and only the segment holding the reference gets angles. Unless configured,
    the reference moves to the largest segment (the first stop there every LiDAR saw):
    a first stop whose only link failed must not leave the others without angles.
    Returns the reference stop.
    """
    reg = config.registration
    order = sorted({k for lidar in lidars for k in lidar.stop_scan})
    full: dict[int, Cloud] = {}
    structure: dict[int, Cloud] = {}
    for k in order:
        points = vehicle_points(lidars, k, recorded)
        full[k] = prepare(points, reg.coarse_voxel_m, 20, reg.num_threads)
        structure[k] = prepare(
            remove_ground(full[k].points_m), reg.coarse_voxel_m, 20, reg.num_threads
        )
    stamp = {
        k: next(
            lidar.scans[lidar.stop_scan[k]].stamp_ns for lidar in lidars if k in lidar.stop_scan
        )
        for k in order
    }
    segment_of: dict[int, int] = {order[0]: 0}
    pose: dict[int, F64] = {order[0]: np.eye(4)}
    broken: dict[int, str] = {}
    n_segments = 1
    for i, b in enumerate(order[1:], start=1):
        reasons = []
        for a in reversed(order[max(0, i - _TURN_LOOKBACK) : i]):
            prior = None
            if odometry is not None:
                prior = se3.invert(odometry.at(stamp[a])) @ odometry.at(stamp[b])
            turn, why = _find_turn(a, b, full, structure, prior, config)
            if turn is not None:
                segment_of[b] = segment_of[a]
                pose[b] = pose[a] @ turn
                break
            reasons.append(f"from stop {a}: {why}")
        else:
            segment_of[b] = n_segments
            n_segments += 1
            pose[b] = np.eye(4)
            broken[b] = "motion unknown (" + "; ".join(reasons) + ")"
    size = {seg: list(segment_of.values()).count(seg) for seg in set(segment_of.values())}
    common = [k for k in order if all(k in lidar.stop_scan for lidar in lidars)]
    if config.selection.reference_stop is None and common:
        best = max(common, key=lambda k: (size[segment_of[k]], -k))
        if size[segment_of[best]] > size[segment_of.get(reference, 0)]:
            reference = best
    home = segment_of.get(reference, 0)
    ref_inv = se3.invert(pose[reference])
    up = np.array([0.0, 0.0, 1.0])
    if odometry is not None:
        notes.append(f"odometry from {odometry.source} seeded the vehicle's motion between stops")
    for lidar in lidars:
        base = recorded.base_from_frame[lidar.frame_id]
        base_inv = se3.invert(base)
        for k in sorted(lidar.stop_scan):
            if segment_of[k] == home:
                motion = ref_inv @ pose[k]
                lidar.chain[k] = base_inv @ motion @ base
                lidar.angles[k] = stop_choice.signed_angle_deg(motion, up)
            else:
                lidar.angles[k] = None
                starts = [j for j in broken if j <= k and segment_of[j] == segment_of[k]]
                if not starts:
                    lidar.dropped[k] = "not connected to the reference stop's group"
                else:
                    start = max(starts)
                    lidar.dropped[k] = (
                        broken[start]
                        if start == k
                        else f"in the group of stops from stop {start}: {broken[start]}"
                    )
    return reference
