"""The planar prior's up (calib.vehicle_up): turn axis where the alignments agree, the
ground normal where they scatter more than the ground's flatness floor."""

from __future__ import annotations

import math

import numpy as np

from syncaudit.calib import se3
from syncaudit.calib.graph import posegraph
from syncaudit.calib.graph.vehicle_up import GROUND_FLOOR_DEG, axis_standard_error_deg, vehicle_up

UP = np.array([0.0, 0.0, 1.0])


def _edges(tilts_deg: list[float]) -> list[posegraph.Edge]:
    """30 deg turns whose axes lean `tilt` deg from z towards x, then y, alternately."""
    edges = []
    for i, tilt in enumerate(tilts_deg):
        lean = math.radians(tilt)
        axis = np.array([math.sin(lean), 0.0, math.cos(lean)])
        if i % 2:
            axis = axis[[1, 0, 2]]
        rot = se3.exp_so3(axis * math.radians(30.0))
        edges.append(
            posegraph.Edge(i, i + 1, se3.make_transform(rot, (0.5, 0.0, 0.0)), np.eye(6), 1.0)
        )
    return edges


def test_standard_error_is_the_robust_spread_over_root_n() -> None:
    edges = _edges([0.4] * 16)
    # Every axis 0.4 deg from z: median 0.4, times 1.4826, over sqrt(16).
    assert math.isclose(axis_standard_error_deg(edges, UP) or 0.0, 1.4826 * 0.4 / 4.0, rel_tol=1e-6)
    # Turns under 5 deg give no axis; fewer than two axes give no error.
    small = posegraph.Edge(0, 1, se3.make_transform(se3.rot_z(0.05), (0, 0, 0)), np.eye(6), 1.0)
    assert axis_standard_error_deg([small, *_edges([0.4])], UP) is None


def test_scattered_alignments_give_way_to_a_flat_ground() -> None:
    tilted = np.array([math.sin(math.radians(0.35)), 0.0, math.cos(math.radians(0.35))])
    ground = np.array([0.0, 0.0, 1.0])
    scattered = vehicle_up(tilted, _edges([0.6, 1.2, 0.3, 0.9] * 3), ground, 0.01, UP)
    assert scattered.source == "ground plane" and np.allclose(scattered.axis, ground)
    assert (scattered.turn_axis_error_deg or 0.0) > GROUND_FLOOR_DEG
    # Axes within 0.03 deg of their mean (z): the turn axis stays, over a tilted ground.
    agreeing = vehicle_up(UP, _edges([0.02, 0.03] * 6), tilted, 0.01, UP)
    assert agreeing.source == "turn axis" and np.allclose(agreeing.axis, UP)
    # Ground normals that disagree across stops are no floor: the turn axis stays.
    uneven = vehicle_up(tilted, _edges([0.6, 1.2, 0.3, 0.9] * 3), ground, 0.2, UP)
    assert uneven.source == "turn axis"
    assert vehicle_up(None, [], None, None, UP).source == "recorded"
    assert vehicle_up(None, [], ground, 0.0, UP).source == "ground plane"
