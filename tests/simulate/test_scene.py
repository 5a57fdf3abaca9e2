"""The ray-cast calibration scene: exact distances to its primitives."""

from __future__ import annotations

import math

import numpy as np
import pytest

from syncaudit.simulate.scene import Box, Pole, Scene


def test_raycast_hits_ground_box_and_pole_exactly() -> None:
    scene = Scene(
        boxes=(Box((10.0, 0.0, 1.0), (2.0, 2.0, 2.0), 0.0, "box", 0.5),),
        poles=(Pole((0.0, 5.0), 0.5, 3.0, 0.9),),
    )
    origin = np.array([0.0, 0.0, 1.0])
    dirs = np.array(
        [
            [1.0, 0.0, 0.0],  # box face at x = 9
            [0.0, 1.0, 0.0],  # pole side at y = 4.5
            [0.0, 0.0, -1.0],  # ground 1 m below
            [0.0, 0.0, 1.0],  # sky
            [1.0, 0.0, -1.0 / 9.0],  # box face, below the top
        ]
    )
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    hits = scene.raycast(origin, dirs)
    assert hits.range_m[0] == pytest.approx(9.0, abs=1e-12)
    assert hits.range_m[1] == pytest.approx(4.5, abs=1e-12)
    assert hits.range_m[2] == pytest.approx(1.0, abs=1e-12)
    assert math.isinf(hits.range_m[3])
    assert hits.range_m[4] == pytest.approx(math.hypot(9.0, 1.0), abs=1e-12)
    assert hits.cos_incidence[0] == pytest.approx(1.0)
    # A rotated box: a ray along its diagonal enters at the corner distance.
    rotated = Scene(
        boxes=(Box((5.0, 0.0, 0.0), (2.0, 2.0, 4.0), math.pi / 4, "box", 0.5),), poles=()
    )
    hit = rotated.raycast(np.array([0.0, 0.0, 1.0]), np.array([[1.0, 0.0, 0.0]]))
    assert hit.range_m[0] == pytest.approx(5.0 - math.sqrt(2.0), abs=1e-12)
