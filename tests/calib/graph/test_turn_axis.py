"""The turn axis (calib.graph.posegraph) leaves out an alignment that tilts out of the plane of motion."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from syncaudit.calib import se3


def test_turn_axis_leaves_out_an_alignment_that_tilts_out_of_the_plane() -> None:
    """A planar vehicle's turns are rotations about one axis: an alignment tilted 0.9 deg
    out of that plane (as an 11 %-overlap one on a bumper drive was) must not pull the
    axis, while small per-alignment noise (0.03 deg) is averaged, not refused."""
    from syncaudit.calib.graph import posegraph

    rng = np.random.default_rng(3)
    tilt = se3.rpy_to_matrix(math.radians(0.4), math.radians(1.7), math.radians(0.9))
    axis = tilt.T @ np.array([0.0, 0.0, 1.0])
    yaws_deg = [0.0, 38.0, 71.0, 104.0, 140.0, 175.0, 212.0, 249.0]

    def edge(a: int, b: int, extra_deg: float) -> posegraph.Edge:
        turn = math.radians(yaws_deg[b] - yaws_deg[a])
        noise = rng.normal(size=3)
        noise *= math.radians(0.03) / float(np.linalg.norm(noise))
        across = np.cross(axis, [1.0, 0.0, 0.0])
        rot = (
            se3.axis_angle_about(across, math.radians(extra_deg))
            if extra_deg
            else se3.axis_angle_about(noise, float(np.linalg.norm(noise)))
        ) @ se3.axis_angle_about(axis, turn)
        return posegraph.Edge(a, b, se3.make_transform(rot, (0.2, 0.1, 0.0)), np.eye(6), 1.0)

    good = [edge(a, a + 1, 0.0) for a in range(7)] + [edge(a, a + 2, 0.0) for a in range(0, 6, 2)]
    bad = edge(3, 5, 0.9)
    hint = axis + np.array([0.05, 0.0, 0.0])

    def error_deg(found: Any) -> float:
        return math.degrees(math.acos(min(1.0, float(found @ axis))))

    assert posegraph.tilting_edges(good, axis, hint) == []
    assert error_deg(posegraph.turn_axis(good, hint)) < 0.01
    assert posegraph.tilting_edges([*good, bad], axis, hint) == [(3, 5)]
    assert error_deg(posegraph.turn_axis([*good, bad], hint)) < 0.01
