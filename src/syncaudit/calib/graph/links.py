"""Which accepted pair alignments link a LiDAR's stops, and the groups of stops they join."""

from __future__ import annotations

from syncaudit.calib.alignment.pairs import pair_edge
from syncaudit.calib.graph import posegraph
from syncaudit.calib.state import LidarState


def accepted_edges(lidar: LidarState, nodes: set[int] | None = None) -> list[posegraph.Edge]:
    """The LiDAR's accepted pair alignments as pose-graph edges (only inside `nodes` if given)."""
    return [
        pair_edge(a, b, lidar.results[(a, b)])
        for a, b, _s, _p in lidar.candidates
        if lidar.results[(a, b)].accepted and (nodes is None or (a in nodes and b in nodes))
    ]


_FIRM_TRANSLATION_INFORMATION = 0.05
"""Stops join a group (one local map) only through alignments at least this well
constrained in translation; weaker accepted ones still close loops inside a group. A weak
alignment that is the only link between two groups can slide along its weak direction
with nothing to contradict it: measured on a roof left/right 32-beam drive, a lone link
with information 0.038 had slid 8 cm and shifted 8 stops of one LiDAR's map by 8 cm
(calibration off by 4.9 cm); correct links there had 0.04-0.40."""


def firm_edges(lidar: LidarState, nodes: set[int] | None = None) -> list[posegraph.Edge]:
    """Accepted alignments firm enough to join stops into a group."""
    return [
        edge
        for edge in accepted_edges(lidar, nodes)
        if lidar.results[(edge.first, edge.second)].after.conditioning.translation_information
        >= _FIRM_TRANSLATION_INFORMATION
    ]


def components(lidar: LidarState) -> list[frozenset[int]]:
    """Groups of kept stops connected by firm accepted alignments."""
    edges = firm_edges(lidar)
    remaining = set(lidar.kept)
    out = []
    while remaining:
        group = frozenset(posegraph.connected(lidar.kept, edges, min(remaining)))
        out.append(group)
        remaining -= group
    return out
