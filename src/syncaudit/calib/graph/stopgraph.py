"""Per-LiDAR pose graphs over its groups of stops, anchored at stops the other LiDARs share."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib import se3
from syncaudit.calib.alignment.pairs import align_pair
from syncaudit.calib.graph import posegraph
from syncaudit.calib.graph.lidar_summary import summarize_lidar
from syncaudit.calib.graph.links import accepted_edges, components, firm_edges
from syncaudit.calib.selection import stop_choice
from syncaudit.calib.settings import CalibConfig
from syncaudit.calib.state import LidarState

F64 = NDArray[np.float64]


def _turn_axis(
    lidar: LidarState, edges: list[posegraph.Edge], outliers: set[tuple[int, int]]
) -> F64 | None:
    """The LiDAR's turn axis from the firm accepted alignments of all its stops (outliers
    left out), else from `edges`.

    The axis is the vehicle's vertical seen from the LiDAR, one for all its groups of
    stops, so every firm alignment estimates it; a weak one (low overlap) can be tilted
    by a degree: measured on a bumper 64-beam drive, one accepted 5-7 alignment off by
    1.24 deg (translation information 0.034) was a sixth of its group's axis estimate,
    which tilted the planar graph's poses by up to 0.48 deg and the calibration by 0.25
    deg / 3.2 cm."""
    firm = [e for e in firm_edges(lidar) if (e.first, e.second) not in outliers]
    axis = posegraph.turn_axis(firm, lidar.up)
    return axis if axis is not None else posegraph.turn_axis(edges, lidar.up)


def _solve(
    lidar: LidarState,
    reference: int,
    nodes: list[int],
    edges: list[posegraph.Edge],
    config: CalibConfig,
) -> posegraph.PoseGraphSolution:
    """Pose graph over `nodes`; outliers are dropped and the graph re-solved without them
    (when every stop stays connected), so the robust kernel's leftover pull is gone too."""
    axis = None
    if config.pose_graph.motion == "planar":
        axis = _turn_axis(lidar, edges, set())
        lidar.turn_axis = axis
    initial = posegraph.spanning_poses(reference, edges)
    solution = posegraph.optimise(reference, initial, edges, config.pose_graph, axis)
    outliers = {(r.first, r.second) for r in solution.residuals if r.outlier}
    if not outliers:
        return solution
    clean = [e for e in edges if (e.first, e.second) not in outliers]
    if posegraph.connected(nodes, clean, reference) != set(nodes):
        return solution
    if axis is not None:
        axis = _turn_axis(lidar, clean, outliers)
        lidar.turn_axis = axis
    again = posegraph.optimise(reference, initial, clean, config.pose_graph, axis)
    return posegraph.PoseGraphSolution(
        again.poses,
        posegraph.residuals(edges, again.poses, config.pose_graph, axis),
        again.error_before,
        again.error_after,
        again.iterations,
    )


_REALIGN_ROTATION_DEG = 0.01
_REALIGN_TRANSLATION_M = 0.002
"""A pair is aligned again, seeded from the pose graph, when its result and the graph
disagree by more than this: GICP may have stopped early along a weak direction."""


def _anchors(lidars: list[LidarState], config: CalibConfig) -> list[int]:
    """Stops at which the LiDARs' local maps are anchored, best first.

    Maps of different LiDARs can only be aligned when anchored at the same vehicle stop,
    and a LiDAR's map can only hold the stops its pose graph connects. Where a featureless
    view splits a LiDAR's stops into groups, each combination of groups that shares a stop
    gives its own map pair (and its own estimate of the extrinsic). The first anchor is
    the configured reference stop, else the shared stop whose groups are largest for the
    weakest LiDAR (earliest on ties).
    """
    groups = {lidar.topic: components(lidar) for lidar in lidars}

    def group_of(lidar: LidarState, stop: int) -> frozenset[int]:
        """The group of the LiDAR's stops that holds `stop`."""
        return next(g for g in groups[lidar.topic] if stop in g)

    common = sorted(set.intersection(*(set(lidar.kept) for lidar in lidars)))
    ranked = sorted(common, key=lambda s: (-min(len(group_of(lidar, s)) for lidar in lidars), s))
    if config.selection.reference_stop is not None:
        first = config.selection.reference_stop
        ranked = [first] + [s for s in ranked if s != first]
    anchors: list[int] = []
    seen: set[tuple[frozenset[int], ...]] = set()
    for stop in ranked:
        key = tuple(group_of(lidar, stop) for lidar in lidars)
        big_enough = min(len(g) for g in key) >= config.selection.min_stops
        if key in seen or (anchors and not big_enough):
            continue
        seen.add(key)
        anchors.append(stop)
    return anchors


def _solve_group(
    lidar: LidarState, group: frozenset[int], anchor: int, config: CalibConfig
) -> None:
    """Pose graph of one group of stops, with one refinement round: pairs that disagree
    with the graph are aligned again from it (GICP may have stopped early along a weak
    direction), then the graph is solved again."""
    nodes = set(group)
    solution = _solve(lidar, anchor, sorted(nodes), accepted_edges(lidar, nodes), config)
    realigned = False
    for (a, b), res in list(lidar.results.items()):
        if a not in nodes or b not in nodes:
            continue
        predicted = se3.invert(solution.poses[a]) @ solution.poses[b]
        rot_deg, trans_m = se3.transform_difference(res.target_from_source, predicted)
        if rot_deg > _REALIGN_ROTATION_DEG or trans_m > _REALIGN_TRANSLATION_M:
            lidar.results[(a, b)] = align_pair(lidar, a, b, predicted, config)
            realigned = True
    if realigned:
        nodes = posegraph.connected(nodes, firm_edges(lidar, nodes), anchor)
        if len(nodes) >= config.selection.min_stops:
            edges = accepted_edges(lidar, nodes)
            solution = _solve(lidar, anchor, sorted(nodes), edges, config)
    if len(nodes) >= config.selection.min_stops:
        lidar.graphs[group] = solution


def poses_at(lidar: LidarState, anchor: int) -> dict[int, F64] | None:
    """The LiDAR's solved poses re-anchored at `anchor` (None if no graph holds it)."""
    for solution in lidar.graphs.values():
        if anchor in solution.poses:
            inv = se3.invert(solution.poses[anchor])
            return {k: inv @ pose for k, pose in solution.poses.items()}
    return None


def graph_lidars(lidars: list[LidarState], config: CalibConfig) -> list[int]:
    """Step 4: anchors, then one pose graph per group of a LiDAR's stops an anchor uses."""
    anchors = _anchors(lidars, config)
    for lidar in lidars:
        groups = components(lidar)
        for anchor in anchors:
            group = next(g for g in groups if anchor in g)
            if group not in lidar.graphs and len(group) >= config.selection.min_stops:
                _solve_group(lidar, group, anchor, config)
    main = anchors[0]
    for lidar in lidars:
        ref_angle = lidar.angles.get(main)
        if ref_angle is not None:
            lidar.angles = {
                k: None if v is None else stop_choice.wrap_deg(v - ref_angle)
                for k, v in lidar.angles.items()
            }
        summarize_lidar(lidar, main, config)
    return anchors
