"""A coarse turn that tilts or rises is no drive on level ground (calib.alignment.turnchain)."""

from __future__ import annotations

import math

import numpy as np

from syncaudit.calib import se3
from syncaudit.calib.alignment.registration import prepare
from syncaudit.calib.alignment.turnchain import verify_turn
from syncaudit.calib.settings import CalibConfig


def test_a_coarse_turn_that_tilts_or_rises_is_not_a_drive_on_level_ground() -> None:
    """The turn chain's second criterion refuses a motion no vehicle on level ground makes
    (a yaw search that converged upside down: tilt 179 deg, as measured on a
    diagonal-mount drive) before looking at the scans; a level turn is judged on them."""
    rng = np.random.default_rng(5)
    walls = [
        np.column_stack([rng.uniform(-8, 8, 400), np.full(400, y), rng.uniform(0, 3, 400)])
        for y in (-6.0, 6.0)
    ] + [
        np.column_stack([np.full(400, x), rng.uniform(-6, 6, 400), rng.uniform(0, 3, 400)])
        for x in (-8.0, 8.0)
    ]
    cloud = prepare(np.concatenate(walls), 0.5, 20, 1)
    config = CalibConfig()
    flipped = se3.make_transform(se3.rpy_to_matrix(math.pi, 0.0, 0.4), (0.1, 0.6, 3.84))
    why = verify_turn((cloud, cloud), (cloud, cloud), flipped, config)
    assert why == "not a motion on level ground (the base tilts 180.0 deg)"
    tilted = se3.make_transform(se3.rpy_to_matrix(0.0, math.radians(12.0), 0.5), (0.3, 0.1, 0.0))
    assert verify_turn((cloud, cloud), (cloud, cloud), tilted, config) == (
        "not a motion on level ground (the base tilts 12.0 deg)"
    )
    assert verify_turn((cloud, cloud), (cloud, cloud), np.eye(4), config) is None
    free = config.model_copy(
        update={"pose_graph": config.pose_graph.model_copy(update={"motion": "free"})}
    )
    assert not (verify_turn((cloud, cloud), (cloud, cloud), flipped, free) or "").startswith(
        "not a motion on level ground"
    )
