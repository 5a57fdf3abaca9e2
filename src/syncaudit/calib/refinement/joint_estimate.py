"""The joint estimate: every LiDAR's stops and the extrinsics in one graph, then refined.

Built after the per-LiDAR pose graphs (the baseline), from what the earlier stages found:
each LiDAR's accepted cross-scan alignments (hand-eye links through the vehicle's motion),
the odometry between consecutive stops when the log has it, and each LiDAR's ground plane.
The extrinsics are seeded by the baseline's estimate when it calibrated, else by the
recorded ones. Where a direction is still free, the ground planes come back; where one is
still loose (1-sigma over half the validation limits), map-to-map GICP on the joint poses
(all stops each LiDAR placed, so the maps cover the whole drive) refines: when accepted
it joins the graph as one more factor on the extrinsic and the graph is solved again. A
direction the graph leaves looser than the validation limits (1-sigma) makes the LiDAR
not calibratable, naming the direction and the stops each LiDAR placed.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib import extrinsics as extr
from syncaudit.calib import io, se3
from syncaudit.calib.alignment.crosspairs import cross_links
from syncaudit.calib.alignment.ground import ground_plane
from syncaudit.calib.alignment.pairs import unless_slid
from syncaudit.calib.alignment.registration import Alignment, align, prepare
from syncaudit.calib.graph import jointgraph, posegraph
from syncaudit.calib.graph.links import accepted_edges, firm_edges
from syncaudit.calib.graph.stopgraph import poses_at
from syncaudit.calib.graph.vehicle_up import GROUND_FLOOR_DEG, VehicleUp, vehicle_up
from syncaudit.calib.refinement.maptomap import NOT_CALIBRATED, compared
from syncaudit.calib.result import (
    AlignmentOut,
    ExtrinsicOut,
    FreeDirectionOut,
    JointLidarOut,
    JointOut,
    SelectionOut,
    TransformOut,
    VehicleUpOut,
)
from syncaudit.calib.settings import CalibConfig
from syncaudit.calib.state import LidarState
from syncaudit.calib.validation import map_consistency

F64 = NDArray[np.float64]
MovingHook = Callable[[jointgraph.JointSolution], tuple[list[jointgraph.Link], dict[int, F64]]]
"""Links and new poses from the scans taken while moving, given the solved graph."""

_ODOM_SIGMA_M = 0.02
_ODOM_SIGMA_FRACTION = 0.02
_ODOM_SIGMA_DEG = 0.3
"""Odometry between consecutive stops: 2 cm plus 2 % of the distance, 0.3 deg (wheel
odometry's scale and yaw errors; the simulator draws 1 % each)."""
_GROUND_FLOOR_M = 0.003
"""Smallest 1-sigma of a LiDAR's ground height (its spread over the stops is used when
larger; the tilt's floor is `vehicle_up.GROUND_FLOOR_DEG`)."""


def _stop_stamp(lidar: LidarState, stop: int) -> int:
    return lidar.scans[lidar.stop_scan[stop]].stamp_ns


def _initial_poses(
    lidars: list[LidarState], anchor: int, exts: dict[int, F64], stops: set[int]
) -> dict[int, F64]:
    """The reference LiDAR's pose at each stop: from its own graph, else another LiDAR's
    graph through the seed extrinsic, else the coarse turn chain."""
    out: dict[int, F64] = {}
    for j, lidar in enumerate(lidars):
        poses = poses_at(lidar, anchor) or {}
        ext = exts.get(j, np.eye(4))
        for k, pose in poses.items():
            out.setdefault(k, ext @ pose @ se3.invert(ext))
    for j, lidar in enumerate(lidars):
        ext = exts.get(j, np.eye(4))
        if anchor not in lidar.chain:
            continue
        inv = se3.invert(lidar.chain[anchor])
        for k, pose in lidar.chain.items():
            out.setdefault(k, ext @ inv @ pose @ se3.invert(ext))
    out[anchor] = np.eye(4)
    return {k: v for k, v in out.items() if k in stops}


def _scan_links(lidars: list[LidarState], sigma_m: float) -> list[jointgraph.Link]:
    """Every LiDAR's accepted cross-scan alignments as links, information at `sigma_m`."""
    links = []
    for j, lidar in enumerate(lidars):
        for edge in accepted_edges(lidar):
            links.append(
                jointgraph.Link(
                    j,
                    edge.first,
                    j,
                    edge.second,
                    edge.first_from_second,
                    posegraph.information(edge, sigma_m),
                    "scan",
                )
            )
    return links


def _odometry_links(
    lidars: list[LidarState],
    stops: list[int],
    odometry: io.Odometry | None,
    base_from_ref: F64,
) -> list[jointgraph.Link]:
    """Odometry between consecutive placed stops, in the reference LiDAR's frame."""
    if odometry is None:
        return []
    stamp = {
        k: next(_stop_stamp(lidar, k) for lidar in lidars if k in lidar.stop_scan) for k in stops
    }
    links = []
    for a, b in itertools.pairwise(stops):
        motion = se3.invert(odometry.at(stamp[a])) @ odometry.at(stamp[b])
        ref_motion = se3.invert(base_from_ref) @ motion @ base_from_ref
        dist_m = float(np.linalg.norm(motion[:3, 3]))
        sigma_m = _ODOM_SIGMA_M + _ODOM_SIGMA_FRACTION * dist_m
        sigma_rad = math.radians(_ODOM_SIGMA_DEG)
        info = np.diag([sigma_rad**-2] * 3 + [sigma_m**-2] * 3)
        links.append(jointgraph.Link(0, a, 0, b, ref_motion, info, "odometry"))
    return links


def _grounds(lidars: list[LidarState]) -> list[jointgraph.Ground]:
    """Each LiDAR's ground plane in its own frame: the median over its kept stops."""
    out = []
    for j, lidar in enumerate(lidars):
        fits = [
            fit
            for k in lidar.kept
            if (
                fit := ground_plane(
                    lidar.scans[lidar.stop_scan[k]].points_m.astype(float), lidar.up
                )
            )
            is not None
        ]
        if len(fits) < 2:
            continue
        normals = np.array([f[0] for f in fits])
        offsets = np.array([f[1] for f in fits])
        normal = np.median(normals, axis=0)
        normal /= np.linalg.norm(normal)
        spread_deg = float(np.degrees(np.median(np.arccos(np.clip(normals @ normal, -1, 1)))))
        spread_m = float(np.median(np.abs(offsets - np.median(offsets))))
        out.append(
            jointgraph.Ground(
                j,
                normal,
                float(np.median(offsets)),
                max(spread_deg, GROUND_FLOOR_DEG),
                max(spread_m, _GROUND_FLOOR_M),
                spread_deg,
            )
        )
    return out


def _up(ref: LidarState, grounds: list[jointgraph.Ground]) -> VehicleUp:
    """The reference LiDAR's up for the planar prior: turn axis or ground normal."""
    ground = next((g for g in grounds if g.lidar == 0), None)
    return vehicle_up(
        ref.turn_axis,
        firm_edges(ref),
        None if ground is None else ground.normal,
        None if ground is None else ground.spread_deg,
        ref.up,
    )


def _refine(
    ref: LidarState,
    other: LidarState,
    solution: jointgraph.JointSolution,
    j: int,
    config: CalibConfig,
) -> Alignment | None:
    """Map-to-map GICP of the other LiDAR's map onto the reference's, both on the joint
    poses of every stop each placed, seeded by the joint extrinsic."""
    ext = solution.extrinsics[j]
    ext_inv = se3.invert(ext)
    mc, reg = config.map_to_map, config.registration
    ref_parts = [
        se3.apply(solution.poses[k], ref.fine[k].points_m) for k in ref.fine if k in solution.poses
    ]
    other_parts = [
        se3.apply(ext_inv @ solution.poses[k] @ ext, other.fine[k].points_m)
        for k in other.fine
        if k in solution.poses
    ]
    if not ref_parts or not other_parts:
        return None
    target = prepare(np.concatenate(ref_parts), mc.voxel_m, mc.neighbours, reg.num_threads)
    source = prepare(np.concatenate(other_parts), mc.voxel_m, mc.neighbours, reg.num_threads)
    m2m = align(
        target,
        source,
        ext,
        mc.limits,
        max_iterations=reg.max_iterations,
        threads=reg.num_threads,
    )
    return unless_slid(m2m, ext, "the joint estimate")


REFINE_SHARE = 0.5
"""The map-to-map refinement runs where some 1-sigma exceeds half the validation limits,
not only where a direction is free: on parking-64-facing-bumper seed 3 the graph left
0.173 deg / 1.56 cm (under the limits) and its estimate was 0.113 deg / 0.905 cm off;
refined, 0.023 deg / 0.53 cm at 0.030 deg / 0.59 cm. On seeds 0-4 of the matrix no other
session that pins every direction is that loose (the next, 0.022 deg / 0.64 cm)."""

_MAX_ROUNDS = 4
_SETTLED_DEG = 1e-3
_SETTLED_M = 1e-5
"""The refinement stops when no extrinsic moved more than 0.001 deg / 0.001 cm in a round."""


def _map_link(m2m: Alignment, j: int, anchor: int, stops: int, sigma_m: float) -> jointgraph.Link:
    """A map-to-map alignment as a factor on the extrinsic, weighted as `stops` cross-scan
    alignments of its mean Hessian (the convention of every scan link: Hessian over the
    links' sigma squared), `stops` being the smaller map's stop count."""
    info = m2m.after.hessian * stops / sigma_m**2
    return jointgraph.Link(0, anchor, j, anchor, m2m.target_from_source, info, "map")


def _refine_to_convergence(
    lidars: list[LidarState],
    anchor: int,
    solution: jointgraph.JointSolution,
    links: list[jointgraph.Link],
    grounds: list[jointgraph.Ground],
    planar: F64 | None,
    config: CalibConfig,
    sigma_m: float,
) -> tuple[jointgraph.JointSolution, list[jointgraph.Link], dict[int, Alignment | None], int]:
    """Map-to-map GICP of a LiDAR's whole map onto the reference's on the joint poses
    (what the baseline uses, over every stop), as a factor in the graph, solved again,
    until the extrinsics stop moving (the maps are rebuilt on each round's poses) -- for
    the LiDARs whose extrinsic the graph leaves weak in some direction only (1-sigma over
    `REFINE_SHARE` of the validation limits). `grounds` and `planar` are the priors the
    graph being refined holds; each round keeps them.

    Run everywhere, it added nothing the cross-LiDAR pairs do not hold and cost 2-5 CPU s:
    measured on seed 0 of the matrix, weighted as one cross pair it changed 11 sessions'
    errors by at most 0.0005 deg / 0.013 cm and pulled the 16-beam parking lot from
    0.015 deg / 0.04 cm to 0.022 / 0.19; weighted as one pair per stop it pulled four of
    five sessions away from the truth (turntable 0.0051 -> 0.0068 deg, a 64-beam roof
    drive 0.071 -> 0.089 cm). Returns the solution, the
    map links of the last round, each LiDAR's last alignment and the rounds solved."""
    ref = lidars[0]
    refinements: dict[int, Alignment | None] = {}
    map_links: list[jointgraph.Link] = []
    rounds = 0
    loose = [j for j in range(1, len(lidars)) if _free(solution, j, config, REFINE_SHARE)]
    for _ in range(_MAX_ROUNDS if loose else 0):
        round_links = []
        for j in loose:
            lidar = lidars[j]
            m2m = _refine(ref, lidar, solution, j, config)
            refinements[j] = m2m
            if m2m is not None and m2m.accepted:
                stops = min(
                    sum(1 for k in ref.fine if k in solution.poses),
                    sum(1 for k in lidar.fine if k in solution.poses),
                )
                round_links.append(_map_link(m2m, j, anchor, stops, sigma_m))
        if not round_links:
            break
        problem = jointgraph.Problem(
            anchor, solution.poses, solution.extrinsics, links + round_links, grounds, planar
        )
        solved = jointgraph.solve(problem, config.pose_graph)
        rounds += 1
        moved = [
            se3.transform_difference(solution.extrinsics[j], solved.extrinsics[j])
            for j in solved.extrinsics
        ]
        solution, map_links = solved, round_links
        if all(d <= _SETTLED_DEG and m <= _SETTLED_M for d, m in moved):
            break
    return solution, map_links, refinements, rounds


def pinned_by_grounds(
    problem: jointgraph.Problem,
    solution: jointgraph.JointSolution,
    grounds: list[jointgraph.Ground],
    config: CalibConfig,
) -> tuple[jointgraph.JointSolution, list[jointgraph.Ground]]:
    """The solution of `problem`, solved again from its seeds with the ground planes where
    it holds none and leaves some extrinsic's direction free; with the ground planes it holds.

    Planar motion cannot see the height along the turn axis, so without the ground planes
    only the cross-LiDAR pairs pin it; where they do not, the ground planes should, before
    the map-to-map refinement: on maps that barely overlap that pinned the height 4.3 cm
    off at a 1-sigma of 0.15 cm (parking-64-facing-bumper seed 3; with the ground planes
    0.06 cm)."""
    if problem.grounds or not grounds:
        return solution, problem.grounds
    if not any(_free(solution, j, config) for j in problem.initial_extrinsics):
        return solution, problem.grounds
    again = dataclasses.replace(problem, grounds=grounds)
    return jointgraph.solve(again, config.pose_graph), grounds


def _reached(link: jointgraph.Link, aligned: list[jointgraph.Link], anchor: int) -> bool:
    """Whether alignments alone connect both stops of `link` to the anchor."""
    edges = [posegraph.Edge(a.stop_a, a.stop_b, np.eye(4), np.eye(6), 1.0) for a in aligned]
    nodes = {a.stop_a for a in aligned} | {a.stop_b for a in aligned} | {anchor}
    reached = posegraph.connected(nodes, edges, anchor)
    return link.stop_a in reached and link.stop_b in reached


def _free(
    solution: jointgraph.JointSolution, j: int, config: CalibConfig, share: float = 1.0
) -> bool:
    """Whether LiDAR j's extrinsic has a direction looser than `share` of the limits."""
    limits = config.validation
    return bool(
        jointgraph.free_directions(
            solution.covariances[j],
            share * limits.max_rotation_deg,
            share * limits.max_translation_cm,
        )
    )


def _free_reason(
    lidar: LidarState,
    free: list[FreeDirectionOut],
    stops: dict[int, list[int]],
    names: list[str],
    mapped: Alignment | None,
) -> str:
    parts = [
        f"{d.kind} {'about' if d.kind == 'rotation' else 'along'} "
        f"({d.axis[0]:.2f}, {d.axis[1]:.2f}, {d.axis[2]:.2f}) in {lidar.frame_id} "
        f"(1-sigma {d.sigma:.2f} {'deg' if d.kind == 'rotation' else 'cm'})"
        for d in free
    ]
    seen = "; ".join(f"{name} placed stops {stops[j]}" for j, name in enumerate(names))
    why = (
        "the motions both LiDARs saw (and the map-to-map refinement) do not pin it"
        if mapped is None
        else "neither the motions both LiDARs saw nor the two maps, aligned on the joint "
        f"poses (overlap {100.0 * mapped.after.overlap:.0f} %) and in the graph, pin it: "
        "record more stops at which both LiDARs see structure"
    )
    return f"{lidar.topic}: the joint graph leaves {', '.join(parts)} unconstrained: {seen}; {why}"


def _select(
    lidars: list[LidarState],
    j: int,
    anchor: int,
    solution: jointgraph.JointSolution,
    base: ExtrinsicOut,
    *,
    calibrated: bool,
    mapped: bool,
    config: CalibConfig,
) -> SelectionOut:
    """Joint, baseline or none for LiDAR j: the joint estimate unless its graph leaves a
    direction free (then the baseline, unless the graph held the two maps' alignment -- the
    baseline's only bridge between the LiDARs -- and still left it free: none; on
    parking-64-facing-bumper seed 4 the joint graph, maps in, left 2.04 cm free, its
    estimate 2.7 cm off, the baseline 3.2 cm) or the baseline's maps agree far better on
    its own poses (`map_consistency.GROSS_MARGIN`: a joint graph that converged wrong).
    Smaller cost differences do not decide: the baseline is the minimiser of much the same cost
    (map-to-map GICP on its own maps), so the cost leans its way. Measured (issue 29):
    at a 1 % margin the cost picked the baseline on parking-64-facing-bumper seed 0
    (lower by 1.02 %; 0.27 deg / 23 cm off against the joint 0.029 deg / 0.94 cm); on
    parking-64-open-bumper seed 4 the joint graph converged 48.5 deg / 135 cm off and
    the baseline's cost was 37 % lower."""
    ref, other = lidars[0], lidars[j]

    def out(method: str, criterion: str, costs: dict[str, float] | None = None) -> SelectionOut:
        costs = costs or {}
        return SelectionOut(
            topic=other.topic,
            method=method,
            criterion=criterion,
            joint_map_cost_m2=costs.get("joint"),
            baseline_map_cost_m2=costs.get("baseline"),
        )

    if not calibrated and mapped:
        return out(
            "none",
            "the joint graph leaves a direction free with the two maps' alignment in it; the "
            "baseline bridges the LiDARs by such an alignment alone",
        )
    if not calibrated:
        return out("baseline", "the joint graph leaves a direction free")
    ref_poses, other_poses = poses_at(ref, anchor), poses_at(other, anchor)
    if base.result is None or ref_poses is None or other_poses is None:
        return out("joint", "the baseline did not calibrate")
    ext_b = np.array(base.result.matrix)
    ext_j = solution.extrinsics[j]
    estimates = {
        "joint": map_consistency.PlacedScans(
            reference=dict(solution.poses),
            other={k: pose @ ext_j for k, pose in solution.poses.items()},
        ),
        "baseline": map_consistency.PlacedScans(
            reference=ref_poses, other={k: ext_b @ pose for k, pose in other_poses.items()}
        ),
    }
    costs = map_consistency.map_costs(ref.fine, other.fine, estimates, config)
    if costs is None:
        return out("joint", "the estimates share fewer than two stops to compare maps on")
    if map_consistency.baseline_far_better(costs):
        return out("baseline", "the baseline's maps agree far better (map cost)", costs)
    return out("joint", "the joint graph pins every direction (map costs reported)", costs)


def joint_extrinsics(
    lidars: list[LidarState],
    anchor: int,
    recorded: extr.RecordedExtrinsics,
    baseline: list[ExtrinsicOut],
    odometry: io.Odometry | None,
    config: CalibConfig,
    moving: MovingHook | None = None,
) -> tuple[JointOut, list[ExtrinsicOut]]:
    """Solve the joint graph, refine it map to map, and judge every LiDAR's extrinsic.

    `moving` (`alignment.moving_scans`) adds the scans taken while moving, registered on
    the poses solved with the cross-LiDAR pairs, as links and poses (judged on that
    solution's covariances), before the map-to-map refinement."""
    ref = lidars[0]
    seeds: dict[int, F64] = {}
    for j, (lidar, base) in enumerate(zip(lidars[1:], baseline, strict=True), start=1):
        rec = recorded.relative(ref.frame_id, lidar.frame_id)
        seeds[j] = np.array(base.result.matrix) if base.result is not None else rec
    # The first solve only seeds the cross-pair search; its links keep the per-LiDAR
    # graphs' weight (edge_sigma_m). At the final weight, with few links and one bad
    # alignment, the robust kernel let it settle in a wrong minimum: parking-64-open-bumper
    # seed 4, 10 scan links, 49.8 deg off, no cross pair found, the joint 48.5 deg off; at
    # 1 cm 3.9 deg off, five cross pairs, then at 0.6 mm 0.005 deg / 0.15 cm.
    link_sigma_m = config.pose_graph.edge_sigma_m
    scan_links = _scan_links(lidars, link_sigma_m)
    placed = {
        j: sorted(
            {k for link in scan_links if link.lidar_a == j for k in (link.stop_a, link.stop_b)}
        )
        for j in range(len(lidars))
    }
    stops = set().union(*placed.values()) | {anchor}
    initial = _initial_poses(lidars, anchor, seeds, stops)
    order = sorted(initial)
    links = scan_links + _odometry_links(
        lidars, order, odometry, recorded.base_from_frame[ref.frame_id]
    )
    links = [link for link in links if link.stop_a in initial and link.stop_b in initial]
    grounds = _grounds(lidars)
    up = _up(ref, grounds)
    planar = up.axis if config.pose_graph.motion == "planar" else None
    problem = jointgraph.Problem(anchor, initial, seeds, links, grounds, planar)
    solution = jointgraph.solve(problem, config.pose_graph)
    kept = grounds
    cross: list[jointgraph.Link] = []
    cross_tried: dict[int, int] = {}
    for j, lidar in enumerate(lidars[1:], start=1):
        found, tried = cross_links(ref, lidar, j, solution.poses, solution.extrinsics[j], config)
        cross += found
        cross_tried[j] = len(tried)
    if cross:
        # The ground and planar priors only seed the cross pairs: the pairs see the ground
        # and the structure themselves, and a flat-ground assumption would bias them. So
        # does odometry (1-2 % scale error) where alignments place the stops: it stays
        # only for the stops no alignment reaches.
        link_sigma_m = config.pose_graph.joint_link_sigma_m
        firm = _scan_links(lidars, link_sigma_m)
        aligned = [x for x in firm if x.stop_a in initial and x.stop_b in initial] + cross
        links = aligned + [
            link
            for link in links
            if link.kind == "odometry" and not _reached(link, aligned, anchor)
        ]
        # Where the ground plane is the firmer up (`vehicle_up`), the alignments cannot be
        # trusted on tilt, and the ground planes and the planar prior about their normal
        # keep tying it. About the turn axis the planar prior is left out too: the axis is
        # a few hundredths of a degree off (0.04 deg on a 64-beam bumper drive, seed 1)
        # and every stop's prior pulls the extrinsic's tilt after it (there 0.034 deg
        # with the prior, 0.005 without; the baseline 0.026).
        kept = grounds if up.source == "ground plane" else []
        planar = planar if up.source == "ground plane" else None
        problem = jointgraph.Problem(
            anchor, solution.poses, solution.extrinsics, links, kept, planar
        )
        solution, kept = pinned_by_grounds(
            problem, jointgraph.solve(problem, config.pose_graph), grounds, config
        )
    if moving is not None:
        added_links, added_poses = moving(solution)
        if added_links:
            links = links + added_links
            problem = jointgraph.Problem(
                anchor,
                {**solution.poses, **added_poses},
                solution.extrinsics,
                links,
                kept,
                planar,
            )
            solution = jointgraph.solve(problem, config.pose_graph)
    solution, map_links, refinements, rounds = _refine_to_convergence(
        lidars, anchor, solution, links, kept, planar, config, link_sigma_m
    )
    mapped = {
        link.lidar_b: alignment
        for link in map_links
        if (alignment := refinements.get(link.lidar_b)) is not None
    }
    limits = config.validation
    names = [lidar.topic for lidar in lidars]
    outs: list[JointLidarOut] = []
    chosen: list[ExtrinsicOut] = []
    selections: list[SelectionOut] = []
    reasons = []
    for j, lidar in enumerate(lidars[1:], start=1):
        rec = recorded.relative(ref.frame_id, lidar.frame_id)
        cov = solution.covariances[j]
        free = [
            FreeDirectionOut(kind=k, axis=a, sigma=s)
            for k, a, s in jointgraph.free_directions(
                cov, limits.max_rotation_deg, limits.max_translation_cm
            )
        ]
        fields: dict[str, Any] = {
            "topic": lidar.topic,
            "frame_id": lidar.frame_id,
            "reference_topic": ref.topic,
            "reference_frame_id": ref.frame_id,
            "recorded": TransformOut.of(rec),
            "stop_angle_disagreement_deg": None,
            "hand_eye_rotation_residual_deg": None,
        }
        m2m = refinements.get(j)
        if free:
            reason = _free_reason(lidar, free, placed, names, mapped.get(j))
            reasons.append(reason)
            ext_out = ExtrinsicOut(
                **fields,
                **{k: v for k, v in NOT_CALIBRATED.items() if k not in fields},
                calibrated=False,
                reason=reason,
                map_to_map=None if m2m is None else AlignmentOut.of(m2m),
            )
        else:
            cal = solution.extrinsics[j]
            ext_out = ExtrinsicOut(
                **fields,
                **compared(cal, rec, [(cal, np.eye(6))], config),
                calibrated=True,
                reason=None,
                map_to_map=None if m2m is None else AlignmentOut.of(m2m),
            )
        base = baseline[j - 1]
        selection = _select(
            lidars,
            j,
            anchor,
            solution,
            base,
            calibrated=not free,
            mapped=j in mapped,
            config=config,
        )
        selections.append(selection)
        chosen.append(base if selection.method == "baseline" else ext_out)
        outs.append(
            JointLidarOut(
                extrinsic=ext_out,
                sigma_deg=math.degrees(
                    math.sqrt(max(float(np.linalg.eigvalsh(cov[:3, :3])[-1]), 0.0))
                ),
                sigma_cm=100.0 * math.sqrt(max(float(np.linalg.eigvalsh(cov[3:, 3:])[-1]), 0.0)),
                free_directions=free,
                scan_links=sum(1 for link in links if link.kind == "scan" and link.lidar_a == j),
                stops=placed[j],
                refinement=None if m2m is None else AlignmentOut.of(m2m),
            )
        )
    kinds = [link.kind for link in links + map_links]
    joint = JointOut(
        chosen=all(sel.method == "joint" for sel in selections),
        stops=order,
        links={
            "scan": kinds.count("scan"),
            "cross": sum(1 for link in cross if link.kind == "cross"),
            "map": kinds.count("map"),
            "odometry": kinds.count("odometry"),
            "moving": kinds.count("moving"),
            "ground": max(len(kept) - 1, 0) if any(g.lidar == 0 for g in kept) else 0,
        },
        lidars=outs,
        error_before=solution.error_before,
        error_after=solution.error_after,
        iterations=solution.iterations,
        reason="; ".join(reasons) or None,
        selection=selections,
        refinement_rounds=rounds,
        up=VehicleUpOut(
            source=up.source,
            axis=(float(up.axis[0]), float(up.axis[1]), float(up.axis[2])),
            turn_axis_error_deg=up.turn_axis_error_deg,
            ground_spread_deg=up.ground_spread_deg,
        ),
    )
    return joint, chosen
