"""Which alignments join stops into groups (calib.graph.links), on hand-built alignments."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hand_alignments import hand_alignment
from syncaudit.calib import se3
from syncaudit.calib.alignment.registration import Alignment
from syncaudit.calib.graph.links import accepted_edges, components, firm_edges
from syncaudit.calib.state import LidarState, SampledScan


def _lidar(results: dict[tuple[int, int], Alignment], kept: list[int]) -> LidarState:
    scan = SampledScan(0, np.zeros((1, 3), dtype=np.float32))
    lidar = LidarState("/lidar", "lidar", [scan], np.array([0.0, 0.0, 1.0]))
    lidar.kept = kept
    lidar.results = results
    lidar.candidates = [(a, b, 30.0, 0.7) for a, b in results]
    return lidar


def test_only_firm_alignments_join_stops_into_groups() -> None:
    """Stops 0-2 and 3-4 are joined by firm alignments, 2-3 only by a weak one (translation
    information 0.03 < 0.05) and 0-2 by a rejected one: two groups, the weak link kept
    for closing loops inside a group."""
    step = se3.make_transform(se3.rot_z(math.radians(30.0)), (0.5, 0.0, 0.0))
    results = {
        (0, 1): hand_alignment(step),
        (1, 2): hand_alignment(step),
        (0, 2): hand_alignment(step @ step, accepted=False),
        (2, 3): hand_alignment(step, translation_information=0.03),
        (3, 4): hand_alignment(step),
    }
    lidar = _lidar(results, [0, 1, 2, 3, 4])
    assert [(e.first, e.second) for e in accepted_edges(lidar)] == [(0, 1), (1, 2), (2, 3), (3, 4)]
    assert [(e.first, e.second) for e in accepted_edges(lidar, {0, 1, 2})] == [(0, 1), (1, 2)]
    assert [(e.first, e.second) for e in firm_edges(lidar)] == [(0, 1), (1, 2), (3, 4)]
    assert components(lidar) == [frozenset({0, 1, 2}), frozenset({3, 4})]
    edge = accepted_edges(lidar)[0]
    assert edge.first_from_second == pytest.approx(step)
    assert edge.strength == 0.2  # the weaker of translation 0.3 and rotation 0.2
