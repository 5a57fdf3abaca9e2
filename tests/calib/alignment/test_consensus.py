"""The cross-LiDAR loop-closure check on known vehicle motions (numpy only, no registration)."""

from __future__ import annotations

import math

import numpy as np

from syncaudit.calib import se3
from syncaudit.calib.alignment.consensus import Motion, consensus

BOUNDS = {"max_translation_m": 0.3, "max_rotation_deg": 3.0}


def _loop(n: int) -> dict[int, np.ndarray]:
    """True vehicle poses on a left-turning loop: 30 deg and 0.8 m per stop."""
    poses, x, y, yaw = {}, 0.0, 0.0, 0.0
    for k in range(n):
        poses[k] = se3.make_transform(se3.rot_z(yaw), (x, y, 0.0))
        x += 0.8 * math.cos(yaw + math.radians(15.0))
        y += 0.8 * math.sin(yaw + math.radians(15.0))
        yaw += math.radians(30.0)
    return poses


def _measure(
    poses: dict[int, np.ndarray], source: str, a: int, b: int, rng: np.random.Generator
) -> Motion:
    """The true motion a -> b with centimetre / 0.05 deg noise."""
    noise = se3.make_transform(
        se3.rot_z(math.radians(rng.normal(0.0, 0.05))), (*rng.normal(0.0, 0.01, 2), 0.0)
    )
    return Motion(source, a, b, se3.invert(poses[a]) @ poses[b] @ noise)


def _measurements(poses: dict[int, np.ndarray], seed: int = 0) -> list[Motion]:
    """Two LiDARs, each aligning every stop with the next two (loops close)."""
    rng = np.random.default_rng(seed)
    n = len(poses)
    return [
        _measure(poses, source, a, b, rng)
        for source in ("front", "rear")
        for a in range(n)
        for b in (a + 1, a + 2)
        if b < n
    ]


def _shifted(motion: Motion, dx_m: float, dy_m: float) -> Motion:
    wrong = motion.first_from_second.copy()
    wrong[:2, 3] += (dx_m, dy_m)
    return Motion(motion.source, motion.first, motion.second, wrong)


def test_consistent_measurements_are_all_kept_and_place_the_stops() -> None:
    poses = _loop(10)
    found = consensus(_measurements(poses), 0, **BOUNDS)
    assert found.removed == [] and found.unresolved is None
    assert sorted(found.poses) == list(range(10))
    for k, pose in found.poses.items():
        rot_deg, trans_m = se3.transform_difference(poses[k], pose)
        assert rot_deg < 0.2 and trans_m < 0.03, (k, rot_deg, trans_m)


def test_one_wrong_link_is_named_and_removed() -> None:
    """The case seen on a bumper drive: one LiDAR's alignment across a link 1.38 m off,
    the other LiDAR's alignments over the same stops right."""
    poses = _loop(10)
    motions = _measurements(poses)
    bad = next(i for i, m in enumerate(motions) if (m.source, m.first, m.second) == ("front", 5, 6))
    motions[bad] = _shifted(motions[bad], 1.1, -0.83)
    found = consensus(motions, 0, **BOUNDS)
    assert [(r.motion.source, r.motion.first, r.motion.second) for r in found.removed] == [
        ("front", 5, 6)
    ]
    assert found.removed[0].translation_m > 0.5 and found.unresolved is None
    for k, pose in found.poses.items():
        assert se3.transform_difference(poses[k], pose)[1] < 0.03


def test_two_wrong_links_are_both_removed() -> None:
    poses = _loop(10)
    motions = _measurements(poses, seed=1)
    for key in (("front", 2, 3), ("rear", 6, 8)):
        i = next(i for i, m in enumerate(motions) if (m.source, m.first, m.second) == key)
        motions[i] = _shifted(motions[i], -0.9, 0.6)
    found = consensus(motions, 0, **BOUNDS)
    removed = {(r.motion.source, r.motion.first, r.motion.second) for r in found.removed}
    assert removed == {("front", 2, 3), ("rear", 6, 8)}


def test_an_error_shared_by_one_cycle_names_no_culprit() -> None:
    """Three stops, three measurements: any one of them could be the wrong one."""
    poses = _loop(3)
    rng = np.random.default_rng(2)
    motions = [_measure(poses, "front", a, b, rng) for a, b in ((0, 1), (1, 2), (0, 2))]
    motions[1] = _shifted(motions[1], 1.2, 0.0)
    found = consensus(motions, 0, **BOUNDS)
    assert found.removed == []
    assert found.unresolved is not None and found.unresolved.translation_m > 0.3


def test_a_bridge_cannot_be_judged_and_other_components_are_not_returned() -> None:
    poses = _loop(6)
    rng = np.random.default_rng(3)
    motions = [_measure(poses, "front", a, a + 1, rng) for a in (0, 1, 3, 4)]
    motions[0] = _shifted(motions[0], 2.0, 0.0)  # a lone link: nothing contradicts it
    found = consensus(motions, 0, **BOUNDS)
    assert found.removed == [] and found.unresolved is None
    assert sorted(found.poses) == [0, 1, 2]
