"""An alignment that slid far along a barely constrained direction is rejected (calib.alignment.pairs), on hand-built alignments."""

from __future__ import annotations

import numpy as np

from hand_alignments import hand_alignment
from syncaudit.calib import se3
from syncaudit.calib.alignment.pairs import unless_slid


def test_a_large_move_along_a_weak_direction_is_rejected_as_slid() -> None:
    """More than 0.5 m from the seed along a direction with information below 0.15: slid."""
    seed = se3.make_transform(np.eye(3), (1.0, 0.0, 0.0))
    moved = se3.make_transform(np.eye(3), (1.8, 0.0, 0.0))
    weak_x = (0.05, 0.5, 0.5)
    slid = unless_slid(hand_alignment(moved, translation_hessian=weak_x), seed, "the seed")
    assert not slid.accepted
    assert slid.reason == (
        "slid 80 cm from the seed along (1.00, 0.00, 0.00), "
        "a direction barely constrained (0.050 < 0.15)"
    )
    firm = hand_alignment(moved, translation_hessian=(0.2, 0.5, 0.5))
    assert unless_slid(firm, seed, "the seed") is firm
    near = hand_alignment(
        se3.make_transform(np.eye(3), (1.4, 0.0, 0.0)), translation_hessian=weak_x
    )
    assert unless_slid(near, seed, "the seed") is near
    rejected = hand_alignment(moved, translation_hessian=weak_x, accepted=False)
    assert unless_slid(rejected, seed, "the seed") is rejected


def test_the_slid_direction_is_weighed_in_the_source_frame() -> None:
    """The move is measured in the target frame and its constraint in the source frame: a
    source whose z axis is the target's x sees a move along the target's x along its z."""
    seed = np.eye(4)
    z_to_x = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    turned = se3.make_transform(z_to_x, (0.8, 0.0, 0.0))
    weak_z = (0.5, 0.5, 0.05)
    assert not unless_slid(hand_alignment(turned, translation_hessian=weak_z), seed, "s").accepted
    straight = se3.make_transform(np.eye(3), (0.8, 0.0, 0.0))
    assert unless_slid(hand_alignment(straight, translation_hessian=weak_z), seed, "s").accepted
