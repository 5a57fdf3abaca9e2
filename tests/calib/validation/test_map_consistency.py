"""The map cost reported beside the choice (calib.map_consistency): maps that agree cost less."""

from __future__ import annotations

import numpy as np
import pytest

from syncaudit.calib import se3
from syncaudit.calib.alignment.registration import Cloud, prepare
from syncaudit.calib.settings import CalibConfig
from syncaudit.calib.validation.map_consistency import (
    PlacedScans,
    baseline_far_better,
    map_costs,
)

pytest.importorskip("small_gicp")


def _room(rng: np.random.Generator) -> np.ndarray:
    """Points on a floor and two walls (every direction constrained)."""
    n = 6000
    floor = np.c_[rng.uniform(-5, 5, n), rng.uniform(-5, 5, n), np.zeros(n)]
    wall_x = np.c_[np.full(n, 5.0), rng.uniform(-5, 5, n), rng.uniform(0, 3, n)]
    wall_y = np.c_[rng.uniform(-5, 5, n), np.full(n, 5.0), rng.uniform(0, 3, n)]
    return np.concatenate([floor, wall_x, wall_y])


def test_the_estimate_whose_maps_agree_costs_less() -> None:
    config = CalibConfig()
    rng = np.random.default_rng(0)
    clouds = {}
    for k in range(3):
        pts = _room(rng) + rng.normal(0.0, 0.005, (18000, 3))
        clouds[k] = prepare(pts, 0.1, 20, 1)
    eye = {k: np.eye(4) for k in clouds}
    right = PlacedScans(reference=eye, other=eye)
    off = se3.make_transform(se3.rot_z(np.radians(0.3)), (0.03, 0.0, 0.02))
    wrong = PlacedScans(reference=eye, other={k: off for k in clouds})
    costs = map_costs(clouds, clouds, {"joint": wrong, "baseline": right}, config)
    assert costs is not None
    assert costs["baseline"] < costs["joint"]
    # Only the stops both estimates placed are compared; fewer than two: no verdict.
    one = PlacedScans(reference={0: np.eye(4)}, other=eye)
    assert map_costs(clouds, clouds, {"joint": one, "baseline": right}, config) is None


@pytest.mark.parametrize(
    ("rotation_deg", "offset_m", "far"),
    [(0.3, 0.03, True), (0.02, 0.002, False)],
)
def test_only_a_gross_difference_hands_the_choice_to_the_baseline(
    rotation_deg: float, offset_m: float, far: bool
) -> None:
    """Two LiDARs' scans of one room (1 cm noise each): a joint placement 0.3 deg / 3 cm
    off (a graph converged wrong) costs about 7 times the right one's (ratio 0.15); 0.02
    deg / 2 mm off (as far apart as two good estimates) 1.4 % more, within the margin."""
    config = CalibConfig()
    rng = np.random.default_rng(1)
    room = _room(rng)

    def scans() -> dict[int, Cloud]:
        return {k: prepare(room + rng.normal(0.0, 0.01, room.shape), 0.1, 20, 1) for k in range(3)}

    reference, other = scans(), scans()
    eye = {k: np.eye(4) for k in reference}
    off = se3.make_transform(se3.rot_z(np.radians(rotation_deg)), (offset_m, 0.0, offset_m))
    estimates = {
        "joint": PlacedScans(reference=eye, other={k: off for k in reference}),
        "baseline": PlacedScans(reference=eye, other=eye),
    }
    costs = map_costs(reference, other, estimates, config)
    assert costs is not None and costs["baseline"] < costs["joint"]
    assert baseline_far_better(costs) is far
