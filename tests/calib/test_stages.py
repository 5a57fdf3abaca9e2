"""Stage helpers of the calibration on hand-built alignments (no registration, no log)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from syncaudit.calib import se3
from syncaudit.calib.links import accepted_edges, components, firm_edges
from syncaudit.calib.pairs import unless_slid
from syncaudit.calib.registration import Alignment, Conditioning, Fit
from syncaudit.calib.state import LidarState, SampledScan


def _alignment(
    target_from_source: np.ndarray,
    *,
    translation_hessian: tuple[float, float, float] = (0.5, 0.5, 0.5),
    translation_information: float = 0.3,
    accepted: bool = True,
) -> Alignment:
    """An alignment whose Hessian's translation block is diagonal (source frame)."""
    hessian = np.eye(6)
    hessian[3:, 3:] = np.diag(translation_hessian)
    cond = Conditioning(translation_information, 0.2, (1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    fit = Fit(0.6, 0.02, cond, 5000, hessian)
    return Alignment(target_from_source, True, 10, fit, fit, accepted, None if accepted else "x")


def test_a_large_move_along_a_weak_direction_is_rejected_as_slid() -> None:
    """More than 0.5 m from the seed along a direction with information below 0.15: slid."""
    seed = se3.make_transform(np.eye(3), (1.0, 0.0, 0.0))
    moved = se3.make_transform(np.eye(3), (1.8, 0.0, 0.0))
    weak_x = (0.05, 0.5, 0.5)
    slid = unless_slid(_alignment(moved, translation_hessian=weak_x), seed, "the seed")
    assert not slid.accepted
    assert slid.reason == (
        "slid 80 cm from the seed along (1.00, 0.00, 0.00), "
        "a direction barely constrained (0.050 < 0.15)"
    )
    firm = _alignment(moved, translation_hessian=(0.2, 0.5, 0.5))
    assert unless_slid(firm, seed, "the seed") is firm
    near = _alignment(se3.make_transform(np.eye(3), (1.4, 0.0, 0.0)), translation_hessian=weak_x)
    assert unless_slid(near, seed, "the seed") is near
    rejected = _alignment(moved, translation_hessian=weak_x, accepted=False)
    assert unless_slid(rejected, seed, "the seed") is rejected


def test_the_slid_direction_is_weighed_in_the_source_frame() -> None:
    """The move is measured in the target frame and its constraint in the source frame: a
    source whose z axis is the target's x sees a move along the target's x along its z."""
    seed = np.eye(4)
    z_to_x = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    turned = se3.make_transform(z_to_x, (0.8, 0.0, 0.0))
    weak_z = (0.5, 0.5, 0.05)
    assert not unless_slid(_alignment(turned, translation_hessian=weak_z), seed, "s").accepted
    straight = se3.make_transform(np.eye(3), (0.8, 0.0, 0.0))
    assert unless_slid(_alignment(straight, translation_hessian=weak_z), seed, "s").accepted


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
        (0, 1): _alignment(step),
        (1, 2): _alignment(step),
        (0, 2): _alignment(step @ step, accepted=False),
        (2, 3): _alignment(step, translation_information=0.03),
        (3, 4): _alignment(step),
    }
    lidar = _lidar(results, [0, 1, 2, 3, 4])
    assert [(e.first, e.second) for e in accepted_edges(lidar)] == [(0, 1), (1, 2), (2, 3), (3, 4)]
    assert [(e.first, e.second) for e in accepted_edges(lidar, {0, 1, 2})] == [(0, 1), (1, 2)]
    assert [(e.first, e.second) for e in firm_edges(lidar)] == [(0, 1), (1, 2), (3, 4)]
    assert components(lidar) == [frozenset({0, 1, 2}), frozenset({3, 4})]
    edge = accepted_edges(lidar)[0]
    assert edge.first_from_second == pytest.approx(step)
    assert edge.strength == 0.2  # the weaker of translation 0.3 and rotation 0.2
