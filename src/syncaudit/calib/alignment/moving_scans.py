"""Scans taken while moving, used in the joint graph: deskewed, registered to the same
LiDAR's stop scans, and kept where the fit is as sharp as a stop pair's.

Called once the joint graph has placed the stops (`joint_estimate`'s hook). For each scan
of a LiDAR outside its still runs:

- inside another LiDAR's still run (the vehicle stood, this LiDAR's run was too short to
  be found): it is a still scan of that stop, so it shares the stop's pose -- no deskew;
- between two placed stops: the sensor's motion over its sweep is the odometry's when the
  log has it, else the motion between the two stops' poses (constant velocity), refined
  by the moving scans' own registrations (central differences of their registered poses,
  since a vehicle leaving a stop moves slower than the stop-to-stop mean); it is deskewed
  to its sweep's middle instant and becomes one more vehicle pose.

Each is registered (GICP) to the nearest stop scans of the same LiDAR before and after it
and accepted on the stop pairs' own tests (error, conditioning, overlap against what the
views allow, no slide) and on sharpness: its error at most `_SHARP_RATIO` times the
median of the LiDAR's accepted stop pairs. A scan with a pose of its own needs two
accepted alignments (one link would only place that pose, adding nothing); a still one
needs one. The accepted alignments are hand-eye links of the stop links' form, their
sigma widened by the deskew's own uncertainty (`_link_sigma_m`). Deskewed scans join only
where `MovingScansConfig.use` says (auto: the stops alone leave an extrinsic loose): their
poses are only as good as the estimated motion (docs/method.md, part B).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib import extrinsics as extr
from syncaudit.calib import io, se3
from syncaudit.calib.alignment import deskew
from syncaudit.calib.alignment.pairs import pair_edge, unless_slid
from syncaudit.calib.alignment.registration import (
    Alignment,
    Cloud,
    align,
    prepare,
    visible_fraction,
)
from syncaudit.calib.graph import jointgraph, posegraph
from syncaudit.calib.result import MovingScansOut
from syncaudit.calib.selection.stop_choice import VehicleStop
from syncaudit.calib.settings import CalibConfig
from syncaudit.calib.state import LidarState, SampledScan

F64 = NDArray[np.float64]

MOVING_KEY_BASE = 1_000_000
"""Pose keys of moving scans: `MOVING_KEY_BASE * (lidar + 1) + scan index` (never a stop)."""
_STILL_TOLERANCE_DEG = 0.5
_STILL_TOLERANCE_M = 0.05
"""A scan inside another LiDAR's still run is taken as still only if its registration puts
it within this of that stop's pose: a LiDAR facing bare ground looks still while moving
(measured: a rear LiDAR over open tarmac gave one 'still' run of 193 scans, 19 s)."""


@dataclass(frozen=True)
class Interval:
    """When something happened, absolute ns."""

    start_ns: float
    end_ns: float


@dataclass
class _Candidate:
    """One moving scan on its way through the stage."""

    lidar: int
    index: int
    sweep: Interval
    mid_ns: float
    key: int
    still_at: int | None = None
    before: int | None = None
    after: int | None = None
    seed: F64 | None = None
    """Reference LiDAR's pose at the scan's instant (anchor frame), like a stop's X_k."""
    velocity: F64 | None = None
    pose: F64 | None = None
    links: list[jointgraph.Link] | None = None
    reason: str | None = None


def _scan_interval(scan: SampledScan) -> Interval:
    """A scan's sweep in absolute time (its stamp alone without a time field)."""
    if scan.sweep is None:
        return Interval(float(scan.stamp_ns), float(scan.stamp_ns))
    return Interval(scan.stamp_ns + scan.sweep.first_ns, scan.stamp_ns + scan.sweep.last_ns)


def still_intervals(
    lidars: list[LidarState], stops: list[VehicleStop]
) -> dict[int, dict[str, Interval]]:
    """Per stop and LiDAR topic, the time its still run shows the vehicle standing: from its
    first scan's first point to its last scan's last point."""
    out: dict[int, dict[str, Interval]] = {}
    by_topic = {lidar.topic: lidar for lidar in lidars}
    for stop in stops:
        out[stop.index] = {}
        for topic, run in stop.runs.items():
            scans = by_topic[topic].scans
            first, last = (
                _scan_interval(scans[run.indices[0]]),
                _scan_interval(scans[run.indices[-1]]),
            )
            out[stop.index][topic] = Interval(first.start_ns, last.end_ns)
    return out


def _odom_pose(odometry: io.Odometry, t_ns: float) -> F64:
    """The odometry's pose at `t_ns`, interpolated at constant velocity between samples."""
    stamps = odometry.stamps_ns
    i = int(np.clip(np.searchsorted(stamps, t_ns), 1, stamps.size - 1))
    t0, t1 = float(stamps[i - 1]), float(stamps[i])
    p0, p1 = odometry.poses[i - 1], odometry.poses[i]
    s = float(np.clip((t_ns - t0) / max(t1 - t0, 1.0), 0.0, 1.0))
    return _interpolate(p0, p1, s)


def _interpolate(start: F64, end: F64, s: float) -> F64:
    """SE(3) pose a share `s` of the way from `start` to `end` (constant body velocity)."""
    velocity = deskew.body_velocity(se3.invert(start) @ end, 1.0)
    rot, trans = deskew.motion_at(velocity, np.array([s]))
    return np.asarray(start @ se3.make_transform(rot[0], trans[0]))


def _sensor_motion(ref_motion: F64, ext: F64) -> F64:
    """The reference LiDAR's motion `ref_motion` seen from LiDAR j (E^-1 M E)."""
    return np.asarray(se3.invert(ext) @ ref_motion @ ext)


class _Stage:
    """Everything the stage reads, so the steps below take only what varies."""

    def __init__(
        self,
        lidars: list[LidarState],
        stops: list[VehicleStop],
        recorded: extr.RecordedExtrinsics,
        odometry: io.Odometry | None,
        config: CalibConfig,
        solution: jointgraph.JointSolution,
    ) -> None:
        self.lidars = lidars
        self.recorded = recorded
        self.odometry = odometry
        self.config = config
        self.exts = {0: np.eye(4), **solution.extrinsics}
        self.poses = solution.poses
        self.still = still_intervals(lidars, stops)
        # A stop's window is its shortest run's: a LiDAR facing bare ground looks still
        # while the vehicle moves, and its run would stretch the stop over the drive.
        self.shortest = {
            k: min(runs.values(), key=lambda i: i.end_ns - i.start_ns)
            for k, runs in self.still.items()
        }
        self.windows = {k: w for k, w in self.shortest.items() if k in self.poses}
        self.base_from_ref = recorded.base_from_frame[lidars[0].frame_id]

    def ref_motion_odometry(self, t0_ns: float, t1_ns: float) -> F64:
        """The reference LiDAR's motion from t0 to t1 by the odometry."""
        assert self.odometry is not None
        base = se3.invert(_odom_pose(self.odometry, t0_ns)) @ _odom_pose(self.odometry, t1_ns)
        return np.asarray(se3.invert(self.base_from_ref) @ base @ self.base_from_ref)


def _place(stage: _Stage, cand: _Candidate, topic: str) -> None:
    """Still at a stop, or between which two placed stops; the seed pose and the motion."""
    for k, window in stage.shortest.items():
        if window.start_ns <= cand.sweep.start_ns and cand.sweep.end_ns <= window.end_ns:
            if topic in stage.still[k]:
                cand.reason = "at a stop this LiDAR has still scans of"
            elif k not in stage.poses:
                cand.reason = "still at a stop the joint graph did not place"
            else:
                cand.still_at, cand.key, cand.seed = k, k, stage.poses[k]
                cand.velocity = np.zeros(6)
            return
    before = [k for k, w in stage.windows.items() if w.end_ns <= cand.mid_ns]
    after = [k for k, w in stage.windows.items() if w.start_ns >= cand.mid_ns]
    if not before or not after:
        cand.reason = "not between two placed stops"
        return
    a, b = (
        max(before, key=lambda k: stage.windows[k].end_ns),
        min(after, key=lambda k: stage.windows[k].start_ns),
    )
    cand.before, cand.after = a, b
    t_a, t_b = stage.windows[a].end_ns, stage.windows[b].start_ns
    x_a, x_b = stage.poses[a], stage.poses[b]
    ext = stage.exts[cand.lidar]
    span_ns = max(cand.sweep.end_ns - cand.sweep.start_ns, 1e7)
    if stage.odometry is not None:
        cand.seed = x_a @ stage.ref_motion_odometry(t_a, cand.mid_ns)
        motion = stage.ref_motion_odometry(cand.mid_ns - span_ns / 2, cand.mid_ns + span_ns / 2)
        cand.velocity = deskew.body_velocity(_sensor_motion(motion, ext), span_ns * 1e-9)
    else:
        s = float(np.clip((cand.mid_ns - t_a) / max(t_b - t_a, 1.0), 0.0, 1.0))
        cand.seed = _interpolate(x_a, x_b, s)
        motion = _sensor_motion(se3.invert(x_a) @ x_b, ext)
        cand.velocity = deskew.body_velocity(motion, max(t_b - t_a, 1.0) * 1e-9)


def _cloud(stage: _Stage, cand: _Candidate) -> Cloud:
    """The candidate's scan deskewed with its current motion, ready for GICP."""
    lidar = stage.lidars[cand.lidar]
    scan = lidar.scans[cand.index]
    reg = stage.config.registration
    points: NDArray[np.generic] = scan.points_m
    if cand.still_at is None:
        assert scan.sweep is not None and cand.velocity is not None
        points, _mid = deskew.deskew_scan(scan.points_m, scan.sweep, cand.velocity)
    return prepare(points, reg.voxel_m, reg.neighbours, reg.num_threads)


def _targets(stage: _Stage, cand: _Candidate, both: bool) -> list[int]:
    """The LiDAR's own placed stop scans nearest in time before and after the scan."""
    lidar = stage.lidars[cand.lidar]
    own = sorted(
        (k for k in lidar.fine if k in stage.windows and k != cand.still_at),
        key=lambda k: stage.windows[k].start_ns,
    )
    earlier = [k for k in own if stage.windows[k].end_ns <= cand.mid_ns]
    later = [k for k in own if stage.windows[k].start_ns >= cand.mid_ns]
    picks = ([earlier[-1]] if earlier else []) + ([later[0]] if later else [])
    picks.sort(
        key=lambda k: abs(0.5 * (stage.windows[k].start_ns + stage.windows[k].end_ns) - cand.mid_ns)
    )
    return picks if both else picks[:1]


def _register(stage: _Stage, cand: _Candidate, k: int, source: Cloud, pose: F64) -> Alignment | str:
    """GICP of the candidate onto the LiDAR's stop k from the candidate's `pose` (the
    reference's pose at its instant): the alignment, or why none was tried."""
    lidar = stage.lidars[cand.lidar]
    ext = stage.exts[cand.lidar]
    seed = np.asarray(se3.invert(ext) @ se3.invert(stage.poses[k]) @ pose @ ext)
    sel, reg = stage.config.selection, stage.config.registration
    target = lidar.fine[k]
    share = visible_fraction(target, source, seed)
    if share < sel.min_predicted_overlap:
        return "its view does not overlap its stops' views"
    result = align(
        target,
        source,
        seed,
        reg.limits,
        max_iterations=reg.max_iterations,
        threads=reg.num_threads,
        expected_overlap=share,
        planar_axis=lidar.up if stage.config.pose_graph.motion == "planar" else None,
    )
    return unless_slid(result, seed, "the stops' motion")


def _stop_pair_error_m(lidar: LidarState) -> float | None:
    errors = [r.after.rmse_m for r in lidar.results.values() if r.accepted]
    return float(np.median(errors)) if errors else None


def _judge(stage: _Stage, cand: _Candidate, result: Alignment | str) -> str | None:
    """Why an alignment of a moving scan is not used (None: used)."""
    if isinstance(result, str):
        return result
    if not result.accepted:
        word = (result.reason or "rejected").split(" ")[0].rstrip(":")
        return f"registration rejected ({word})"
    typical = _stop_pair_error_m(stage.lidars[cand.lidar])
    ratio = stage.config.moving_scans.sharp_ratio
    if typical is not None and result.after.rmse_m > ratio * typical:
        return f"blurred: error over {ratio:g}x the stop pairs' median"
    return None


def _pose_from(stage: _Stage, cand: _Candidate, k: int, result: Alignment) -> F64:
    """The reference's pose at the candidate's instant from its alignment onto stop k."""
    ext = stage.exts[cand.lidar]
    return np.asarray(stage.poses[k] @ ext @ result.target_from_source @ se3.invert(ext))


def _first_pass(stage: _Stage, cand: _Candidate) -> None:
    """Register onto the nearest stop scan with the initial motion: the candidate's pose."""
    assert cand.seed is not None
    targets = _targets(stage, cand, both=False)
    if not targets:
        cand.reason = "this LiDAR placed no stop scan to register it to"
        return
    k = targets[0]
    result = _register(stage, cand, k, _cloud(stage, cand), cand.seed)
    reason = _judge(stage, cand, result)
    if reason is not None or isinstance(result, str):
        cand.reason = reason
        return
    cand.pose = _pose_from(stage, cand, k, result)


def _refine_velocities(stage: _Stage, gap: list[_Candidate]) -> None:
    """Constant-velocity motion of each registered scan of one gap from its neighbours'
    registered poses (the stops at both ends included): central differences."""
    first = gap[0]
    assert first.before is not None and first.after is not None
    ext = stage.exts[first.lidar]
    track: list[tuple[float, F64]] = [
        (stage.windows[first.before].end_ns, stage.poses[first.before])
    ]
    track += [(c.mid_ns, c.pose) for c in gap if c.pose is not None]
    track.append((stage.windows[first.after].start_ns, stage.poses[first.after]))
    for i in range(1, len(track) - 1):
        (t0, p0), (t1, p1) = track[i - 1], track[i + 1]
        cand = next(c for c in gap if c.pose is not None and c.mid_ns == track[i][0])
        motion = _sensor_motion(se3.invert(p0) @ p1, ext)
        cand.velocity = deskew.body_velocity(motion, max(t1 - t0, 1.0) * 1e-9)


def _link_sigma_m(stage: _Stage, cand: _Candidate) -> float:
    """The 1-sigma of a moving scan's links: a stop link's, combined with the deskew's own
    uncertainty -- `velocity_uncertainty` of how far the deskew moved the points over half
    the sweep at the scan's median range (the motion is an estimate, not a measurement)."""
    sigma_m = stage.config.pose_graph.edge_sigma_m
    if cand.still_at is not None or cand.velocity is None:
        return sigma_m
    scan = stage.lidars[cand.lidar].scans[cand.index]
    range_m = float(np.median(np.linalg.norm(scan.points_m, axis=1)))
    half_sweep_s = 0.5 * (cand.sweep.end_ns - cand.sweep.start_ns) * 1e-9
    moved_m = (
        float(np.linalg.norm(cand.velocity[3:]))
        + float(np.linalg.norm(cand.velocity[:3])) * range_m
    ) * half_sweep_s
    extra_m = stage.config.moving_scans.velocity_uncertainty * moved_m
    return float(np.hypot(sigma_m, extra_m))


def _final_pass(stage: _Stage, cand: _Candidate) -> None:
    """Register onto the nearest stop scans before and after from the candidate's pose
    with its final motion; keep the accepted alignments as links."""
    assert cand.pose is not None
    if cand.still_at is not None:
        off_deg, off_m = se3.transform_difference(stage.poses[cand.still_at], cand.pose)
        if off_deg > _STILL_TOLERANCE_DEG or off_m > _STILL_TOLERANCE_M:
            cand.reason = "registered away from the stop it was taken at (the vehicle moved)"
            return
    source = _cloud(stage, cand)
    links: list[jointgraph.Link] = []
    reasons = []
    for k in _targets(stage, cand, both=True):
        result = _register(stage, cand, k, source, cand.pose)
        reason = _judge(stage, cand, result)
        if reason is not None or isinstance(result, str):
            reasons.append(reason or "rejected")
            continue
        info = posegraph.information(pair_edge(k, cand.key, result), _link_sigma_m(stage, cand))
        links.append(
            jointgraph.Link(
                cand.lidar, k, cand.lidar, cand.key, result.target_from_source, info, "moving"
            )
        )
    needed = 1 if cand.still_at is not None else 2
    if len(links) >= needed:
        cand.links = links
        return
    if links:
        cand.reason = "aligned to one stop only (a pose of its own needs two)"
    else:
        cand.reason = reasons[0] if reasons else "no stop scan to register it to"


def _choose(gap: list[_Candidate], most: int) -> tuple[list[_Candidate], list[_Candidate]]:
    """At most `most` of one gap's moving scans, evenly spread (neighbouring sweeps see
    nearly the same view, and each costs two or three GICPs); and the others."""
    if len(gap) <= most:
        return gap, []
    picks = {round((i + 1) * len(gap) / (most + 1) - 0.5) for i in range(most)}
    return [c for i, c in enumerate(gap) if i in picks], [
        c for i, c in enumerate(gap) if i not in picks
    ]


def _deskewed_wanted(solution: jointgraph.JointSolution, config: CalibConfig) -> tuple[bool, str]:
    """Whether deskewed scans join the graph (`MovingScansConfig.use`), and if not, why:
    in auto, only where the stops alone leave some extrinsic loose (its 1-sigma above
    `weak_share` of the validation limits) -- a data criterion, never the truth."""
    use = config.moving_scans.use
    share = config.moving_scans.weak_share
    limits = config.validation
    worst_deg, worst_cm = 0.0, 0.0
    for cov in solution.covariances.values():
        rot_var, trans_var = (float(np.linalg.eigvalsh(b)[-1]) for b in (cov[:3, :3], cov[3:, 3:]))
        worst_deg = max(worst_deg, math.degrees(math.sqrt(max(rot_var, 0.0))))
        worst_cm = max(worst_cm, 100.0 * math.sqrt(max(trans_var, 0.0)))
    if use != "auto":
        return use == "always", (
            f"the configuration says {use} (the stops alone leave an extrinsic's 1-sigma at "
            f"{worst_deg:.3f} deg / {worst_cm:.2f} cm)"
        )
    if worst_deg > share * limits.max_rotation_deg or worst_cm > share * limits.max_translation_cm:
        return True, (
            f"the stops alone leave an extrinsic's 1-sigma at {worst_deg:.3f} deg / "
            f"{worst_cm:.2f} cm (over {share:g} of the limits)"
        )
    return False, (
        f"the stops alone pin every extrinsic (1-sigma up to {worst_deg:.3f} deg / "
        f"{worst_cm:.2f} cm, under {share:g} of the limits)"
    )


def moving_links(
    lidars: list[LidarState],
    stops: list[VehicleStop],
    recorded: extr.RecordedExtrinsics,
    odometry: io.Odometry | None,
    config: CalibConfig,
    notes: list[str],
    solution: jointgraph.JointSolution,
) -> tuple[list[jointgraph.Link], dict[int, F64]]:
    """Every LiDAR's usable moving scans as joint-graph links on the solved stop poses, and
    the seeds of the poses they add; each LiDAR's `moving` report filled in and one note
    per LiDAR saying what was used."""
    stage = _Stage(lidars, stops, recorded, odometry, config, solution)
    deskewed_wanted, why = _deskewed_wanted(solution, config)
    notes.append(f"moving scans {'deskewed' if deskewed_wanted else 'not deskewed'}: {why}")
    links: list[jointgraph.Link] = []
    poses: dict[int, F64] = {}
    for j, lidar in enumerate(lidars):
        still = {i for stop in stops for i in getattr(stop.runs.get(lidar.topic), "indices", ())}
        stamps = [s.stamp_ns for s in lidar.scans]
        period_ns = float(np.median(np.diff(stamps))) if len(stamps) > 1 else 1e8
        cands: list[_Candidate] = []
        rejected: Counter[str] = Counter()
        for i, scan in enumerate(lidar.scans):
            if i in still:
                continue
            refused = deskew.refusal(scan.sweep, period_ns)
            if refused is not None:
                rejected[f"not deskewable: {refused.split(' (')[0]}"] += 1
                continue
            sweep = _scan_interval(scan)
            cand = _Candidate(
                j, i, sweep, 0.5 * (sweep.start_ns + sweep.end_ns), MOVING_KEY_BASE * (j + 1) + i
            )
            _place(stage, cand, lidar.topic)
            if cand.reason is not None:
                rejected[cand.reason] += 1
                continue
            cands.append(cand)
        gaps: dict[tuple[int, int], list[_Candidate]] = {}
        tried = [c for c in cands if c.still_at is not None]
        if config.moving_scans.use == "never":
            rejected["not used: the configuration says never"] += len(tried)
            tried = []
        for cand in cands:
            if cand.still_at is None:
                assert cand.before is not None and cand.after is not None
                gaps.setdefault((cand.before, cand.after), []).append(cand)
        most = config.moving_scans.max_per_gap
        for gap in gaps.values():
            if not deskewed_wanted:
                rejected[
                    "not used: the configuration says never"
                    if config.moving_scans.use == "never"
                    else "not deskewed: the stops alone pin every extrinsic"
                ] += len(gap)
                continue
            chosen, left = _choose(gap, most)
            tried += chosen
            if left:
                rejected[f"not tried (at most {most} between two stops)"] += len(left)
        for cand in tried:
            _first_pass(stage, cand)
        if odometry is None:
            for gap in gaps.values():
                registered = [c for c in gap if c.pose is not None and c.still_at is None]
                if registered:
                    _refine_velocities(stage, registered)
        for cand in tried:
            if cand.pose is not None:
                _final_pass(stage, cand)
            if cand.links:
                links += cand.links
                if cand.still_at is None:
                    assert cand.pose is not None
                    poses[cand.key] = cand.pose
            else:
                rejected[cand.reason or "rejected"] += 1
        used = sum(1 for c in tried if c.links)
        seen = len(lidar.scans) - len(still)
        lidar.moving = MovingScansOut(
            seen=seen,
            deskewed=sum(1 for c in tried if c.still_at is None),
            still_at_stop=sum(1 for c in tried if c.still_at is not None and c.links),
            used=used,
            motion_source=(
                None
                if not any(c.still_at is None for c in tried)
                else "odometry"
                if odometry is not None
                else "the stops' poses, refined by the moving scans' registrations"
            ),
            rejected=dict(rejected),
        )
        if seen:
            why = "; ".join(f"{n} {r}" for r, n in rejected.most_common())
            notes.append(
                f"{lidar.topic}: {used} of {seen} scan(s) taken while moving used in the joint "
                f"graph ({lidar.moving.still_at_stop} still at another LiDAR's stop, "
                f"{lidar.moving.deskewed} deskewed and registered)" + (f"; {why}" if why else "")
            )
    return links, poses
