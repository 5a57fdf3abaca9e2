"""Cross-LiDAR scan pairs: one LiDAR's stop scan aligned onto another LiDAR's at another stop.

Once the joint graph has placed the vehicle, a turn makes one LiDAR see at stop b what the
other saw at stop a. Such a pair measures `X_a^-1 X_b E` directly: a factor on two stop
poses and the extrinsic, in the graph with every other alignment, rather than one map
built on fixed poses and aligned once (which carries the poses' errors into the extrinsic
unweighted: measured on a 32-beam turntable session, a map-to-map refinement on the joint
poses left 0.043 deg of pitch where the per-LiDAR baseline had 0.008). Pairs are chosen by
the overlap their views allow at the joint estimate and judged as cross-scan alignments.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib import se3
from syncaudit.calib.alignment.pairs import pair_edge, unless_slid
from syncaudit.calib.alignment.registration import Alignment, align, visible_fraction
from syncaudit.calib.graph import jointgraph, posegraph
from syncaudit.calib.settings import CalibConfig
from syncaudit.calib.state import LidarState

F64 = NDArray[np.float64]


def cross_links(
    ref: LidarState,
    other: LidarState,
    j: int,
    poses: dict[int, F64],
    ext: F64,
    config: CalibConfig,
) -> tuple[list[jointgraph.Link], list[tuple[int, int, Alignment]]]:
    """Aligned pairs (reference stop a, other LiDAR's stop b) whose views overlap at the
    joint estimate, the best `max_pairs_per_scan` per reference stop: the accepted ones as
    links, and every alignment tried."""
    sel, reg = config.selection, config.registration
    chosen: list[tuple[float, int, int, F64]] = []
    for a in sorted(k for k in ref.fine if k in poses):
        row = []
        for b in sorted(k for k in other.fine if k in poses):
            seed = se3.invert(poses[a]) @ poses[b] @ ext
            share = visible_fraction(ref.fine[a], other.fine[b], seed)
            if share >= sel.min_predicted_overlap:
                row.append((share, a, b, seed))
        row.sort(key=lambda c: -c[0])
        chosen += row[: sel.max_pairs_per_scan]
    links, tried = [], []
    for share, a, b, seed in chosen:
        result = align(
            ref.fine[a],
            other.fine[b],
            seed,
            reg.limits,
            max_iterations=reg.max_iterations,
            threads=reg.num_threads,
            expected_overlap=share,
        )
        result = unless_slid(result, seed, "the joint estimate")
        tried.append((a, b, result))
        if result.accepted:
            edge = pair_edge(a, b, result)
            info = posegraph.information(edge, config.pose_graph.joint_link_sigma_m)
            links.append(jointgraph.Link(0, a, j, b, result.target_from_source, info, "cross"))
    return links, tried
