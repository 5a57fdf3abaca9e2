"""Cross-LiDAR loop-closure check: the vehicle's motion between stops seen by every LiDAR.

Every accepted pair alignment of every LiDAR, carried into the base frame through the
recorded extrinsic, measures the same thing: how the vehicle moved between two stops. On
a flat floor that motion is planar (x, y, yaw), so once the yaws are known the positions
follow from a *linear* least-squares problem: no initial guess to get wrong, however far
off one measurement is. A wrong link (a coarse motion 1.15 m off whose pair alignment
converged next to it) shows as a fit that leaves some measurement beyond the bound. The
culprit is the one measurement whose removal leaves the rest within the bound; when
several could be (they share one cycle, and nothing tells which is wrong) nothing is
removed and the disagreement is reported. When no single removal is enough (two wrong
links), a least-absolute-residual fit names the worst, if the measurements beyond the
bound are a minority; and the search repeats.

The bound is generous (a recorded extrinsic off by a few degrees and centimetres moves a
LiDAR's view of the vehicle's motion by well under it); least squares spreads an error
over the cycles through it (a 1.38 m wrong link showed 46 cm), so the check is for gross
errors only; the pose graphs do the fine work.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib import se3

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class Motion:
    """One LiDAR's measurement of the vehicle's motion between two stops (base frame)."""

    source: str
    """Who measured it (a LiDAR topic)."""
    first: int
    second: int
    first_from_second: F64


@dataclass(frozen=True)
class Misfit:
    """A measurement and how far it is from the consensus of all the others."""

    motion: Motion
    translation_m: float
    rotation_deg: float


@dataclass(frozen=True)
class Consensus:
    """Planar vehicle poses agreed by the measurements, and the measurements removed."""

    poses: dict[int, F64]
    """Per stop connected to the anchor, the vehicle's pose relative to it (base frame)."""
    removed: list[Misfit]
    unresolved: Misfit | None
    """The worst remaining measurement when it exceeds the bound but cannot be singled out."""


def _yaw(transform: F64) -> float:
    return math.atan2(float(transform[1, 0]), float(transform[0, 0]))


def _wrap(angle_rad: F64) -> F64:
    return np.asarray((angle_rad + np.pi) % (2.0 * np.pi) - np.pi)


def _components(nodes: list[int], edges: list[Motion]) -> list[list[int]]:
    parent = {n: n for n in nodes}

    def find(n: int) -> int:
        while parent[n] != n:
            parent[n] = parent[parent[n]]
            n = parent[n]
        return n

    for e in edges:
        parent[find(e.first)] = find(e.second)
    groups: dict[int, list[int]] = {}
    for n in nodes:
        groups.setdefault(find(n), []).append(n)
    return [sorted(g) for g in groups.values()]


def _solve(
    nodes: list[int], edges: list[Motion], anchors: set[int], weights: F64 | None = None
) -> tuple[dict[int, float], dict[int, F64], F64, F64]:
    """Weighted least-squares yaws and positions (each component's anchor fixed), and each
    edge's translation (m) and yaw (rad) residual."""
    index = {n: i for i, n in enumerate(nodes)}
    n_nodes = len(nodes)
    first = np.array([index[e.first] for e in edges], dtype=np.int64)
    second = np.array([index[e.second] for e in edges], dtype=np.int64)
    rows = np.arange(len(edges))
    incidence = np.zeros((len(edges), n_nodes))
    incidence[rows, first] = -1.0
    incidence[rows, second] = 1.0
    free = np.array([n not in anchors for n in nodes])
    root_w = np.ones(len(edges)) if weights is None else np.sqrt(weights)
    design = incidence[:, free] * root_w[:, None]
    measured_yaw = np.array([_yaw(e.first_from_second) for e in edges])
    # Yaws: unwrap along a spanning tree first, then a least-squares correction.
    yaw = np.zeros(n_nodes)
    placed = np.array([n in anchors for n in nodes])
    while not placed.all():
        grew = False
        for k in range(len(edges)):
            a, b = first[k], second[k]
            if placed[a] and not placed[b]:
                yaw[b], placed[b], grew = yaw[a] + measured_yaw[k], True, True
            elif placed[b] and not placed[a]:
                yaw[a], placed[a], grew = yaw[b] - measured_yaw[k], True, True
        if not grew:
            break
    for _ in range(2):
        residual = _wrap(measured_yaw - (yaw[second] - yaw[first]))
        step = np.linalg.lstsq(design, residual * root_w, rcond=None)[0]
        yaw[free] += step
    # Positions: p_b - p_a = R(yaw_a) t_ab, linear once the yaws are fixed.
    local = np.array([e.first_from_second[:2, 3] for e in edges])
    c, s = np.cos(yaw[first]), np.sin(yaw[first])
    rhs = np.c_[c * local[:, 0] - s * local[:, 1], s * local[:, 0] + c * local[:, 1]]
    xy = np.zeros((n_nodes, 2))
    xy[free] = np.linalg.lstsq(design, rhs * root_w[:, None], rcond=None)[0]
    t_res = np.linalg.norm(rhs - (xy[second] - xy[first]), axis=1)
    y_res = np.abs(_wrap(measured_yaw - (yaw[second] - yaw[first])))
    return (
        {n: float(yaw[i]) for n, i in index.items()},
        {n: xy[i] for n, i in index.items()},
        t_res,
        y_res,
    )


def _fit(
    edges: list[Motion],
    anchor: int,
    bounds: tuple[float, float],
    weights: F64 | None = None,
) -> tuple[dict[int, float], dict[int, F64], F64, list[Misfit]]:
    """Fit, then each edge's residual as a fraction of the bounds (> 1: beyond)."""
    if not edges:
        return {anchor: 0.0}, {anchor: np.zeros(2)}, np.zeros(0), []
    nodes = sorted({e.first for e in edges} | {e.second for e in edges} | {anchor})
    anchors = {anchor if anchor in g else g[0] for g in _components(nodes, edges)}
    yaw, xy, t_res, y_res = _solve(nodes, edges, anchors, weights)
    score = np.maximum(t_res / bounds[0], np.degrees(y_res) / bounds[1])
    misfits = [
        Misfit(e, float(t), float(np.degrees(y)))
        for e, t, y in zip(edges, t_res, y_res, strict=True)
    ]
    return yaw, xy, score, misfits


_ROBUST_ITERATIONS = 30
_ROBUST_FLOOR = 0.02
"""IRLS towards least absolute residuals: weight 1 / max(score, floor) per edge."""


def _robust_worst(edges: list[Motion], anchor: int, bounds: tuple[float, float]) -> int:
    """With several bad measurements (no single removal restores consistency): the worst
    of those a least-absolute-residual fit leaves beyond the bound, when they are a
    minority (at most a third of the measurements); else -1.

    Least absolute residuals put a gross error on the measurement that carries it rather
    than spreading it over every edge of its cycles, as least squares does."""
    weights = np.ones(len(edges))
    score = np.zeros(len(edges))
    for _ in range(_ROBUST_ITERATIONS):
        score = _fit(edges, anchor, bounds, weights)[2]
        weights = 1.0 / np.maximum(score, _ROBUST_FLOOR)
    beyond = int(np.sum(score > 1.0))
    if beyond == 0 or beyond * 3 > len(edges):
        return -1
    return int(np.argmax(score))


def consensus(
    motions: list[Motion],
    anchor: int,
    *,
    max_translation_m: float,
    max_rotation_deg: float,
) -> Consensus:
    """Remove the measurements that disagree with all the others beyond the bound (one at
    a time, worst first, while one stands out), and the planar poses the rest agree on.

    `anchor` is the origin of the poses (other components are fixed at their smallest
    stop while fitting, and their poses are not returned).
    """
    kept = list(motions)
    removed: list[Misfit] = []
    unresolved: Misfit | None = None
    yaw: dict[int, float] = {anchor: 0.0}
    xy: dict[int, F64] = {anchor: np.zeros(2)}
    bounds = (max_translation_m, max_rotation_deg)
    while kept:
        yaw, xy, score, misfits = _fit(kept, anchor, bounds)
        if float(score.max()) <= 1.0:
            break
        # The one measurement whose removal leaves the rest consistent, if exactly one.
        restoring = [
            i
            for i in np.argsort(score)[::-1]
            if float(_fit(kept[:i] + kept[i + 1 :], anchor, bounds)[2].max(initial=0.0)) <= 1.0
        ]
        if len(restoring) > 1:
            unresolved = misfits[int(np.argmax(score))]
            break
        culprit = int(restoring[0]) if restoring else _robust_worst(kept, anchor, bounds)
        if culprit < 0:
            unresolved = misfits[int(np.argmax(score))]
            break
        removed.append(misfits[culprit])
        del kept[culprit]
    nodes = sorted({e.first for e in kept} | {e.second for e in kept} | {anchor})
    home = next(g for g in _components(nodes, kept) if anchor in g)
    poses = {
        n: se3.make_transform(se3.rot_z(yaw[n]), (float(xy[n][0]), float(xy[n][1]), 0.0))
        for n in home
    }
    return Consensus(poses=poses, removed=removed, unresolved=unresolved)
