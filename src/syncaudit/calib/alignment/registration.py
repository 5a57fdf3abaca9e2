"""Scan registration with small_gicp: preprocessing, GICP, overlap/error and degeneracy tests.

small_gicp does the work (voxel grid, covariances, KD-tree, GICP); this module decides
whether a result can be trusted: how much of the source overlaps the target, the final
point-to-plane error, and whether the eigenvalues of the point-to-plane Hessian leave a
direction unconstrained (a degenerate alignment is flagged, never trusted).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib import se3
from syncaudit.calib.settings import AlignmentLimits
from syncaudit.errors import MissingExtraError

F64 = NDArray[np.float64]
_ROTATION_EPS_RAD = 1e-4
_TRANSLATION_EPS_M = 1e-4
"""GICP stops when an update is below these (0.006 deg, 0.1 mm): finer limits only make
it oscillate between correspondence sets without changing the result measurably."""


def backend() -> Any:
    """The small_gicp module, or a one-line MissingExtraError (exit 64) naming the extra to install.

    Before the first import, OpenMP threads are told to sleep rather than spin while
    waiting (unless OMP_WAIT_POLICY is set already): on a busy 2-core machine spinning
    threads starve each other, measured here as 61 s instead of 4 s for one calibration.
    """
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    try:
        import small_gicp
    except ImportError:
        raise MissingExtraError(
            "LiDAR calibration needs the optional extra: pip install 'syncaudit[calib]' "
            "(small_gicp is missing)"
        ) from None
    return small_gicp


@dataclass(frozen=True)
class Cloud:
    """A voxel-downsampled cloud ready for GICP: points, normals, covariances and KD-tree."""

    points_m: F64
    normals: F64
    gicp: Any
    tree: Any
    voxel_m: float

    @property
    def size(self) -> int:
        """Number of points."""
        return int(self.points_m.shape[0])


def prepare(points_m: NDArray[Any], voxel_m: float, neighbours: int, threads: int) -> Cloud:
    """Downsample (single-threaded: deterministic), then estimate normals and covariances."""
    sg = backend()
    raw = np.ascontiguousarray(points_m, dtype=np.float64)
    cloud = sg.voxelgrid_sampling(sg.PointCloud(raw), voxel_m, num_threads=1)
    tree = sg.KdTree(cloud, num_threads=threads)
    sg.estimate_normals_covariances(cloud, tree=tree, num_neighbors=neighbours, num_threads=threads)
    points = np.asarray(cloud.points())[:, :3].copy()
    normals = np.asarray(cloud.normals())[:, :3].copy()
    return Cloud(points_m=points, normals=normals, gicp=cloud, tree=tree, voxel_m=voxel_m)


@dataclass(frozen=True)
class Conditioning:
    """Eigen-analysis of the point-to-plane Hessian of the overlapping points.

    The translation block is sum(n n^T) over the correspondences (n: target normal in the
    source frame), the rotation block sum(m m^T) with m = (p x n) / |p| (p: source point,
    so rotation is about the source LiDAR), both divided by the number of correspondences. Their smallest
    eigenvalue is the mean squared constraint a point puts on the weakest direction: 1 for
    a direction every point pins down, near 0 for one nothing constrains (sliding along a
    lone wall, turning above bare ground).
    """

    translation_information: float
    rotation_information: float
    weakest_translation: tuple[float, float, float]
    weakest_rotation_axis: tuple[float, float, float]

    def describe(self) -> str:
        """The weaker of the two blocks as text."""
        t, r = self.weakest_translation, self.weakest_rotation_axis
        return (
            f"translation along ({t[0]:.2f}, {t[1]:.2f}, {t[2]:.2f}): "
            f"{self.translation_information:.4f}; rotation about "
            f"({r[0]:.2f}, {r[1]:.2f}, {r[2]:.2f}): {self.rotation_information:.4f}"
        )


_NO_CONDITIONING = Conditioning(0.0, 0.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


def _weakest(rows: F64) -> tuple[float, tuple[float, float, float]]:
    """Smallest eigenvalue of mean(rows^T rows) and its eigenvector (sign-normalised)."""
    hessian = rows.T @ rows / max(rows.shape[0], 1)
    values, vectors = np.linalg.eigh(hessian)
    vec = vectors[:, 0]
    vec = vec if vec[int(np.argmax(np.abs(vec)))] >= 0 else -vec
    return max(float(values[0]), 0.0), (float(vec[0]), float(vec[1]), float(vec[2]))


@dataclass(frozen=True)
class Fit:
    """How well a transformed source lies on the target, and how well it is constrained."""

    overlap: float
    """Fraction of source points with a target point within the overlap distance."""
    rmse_m: float
    """Point-to-plane RMS distance of those overlapping points (inf when none)."""
    conditioning: Conditioning
    correspondences: int
    """Number of overlapping source points with a target normal (the Hessian's sample)."""
    hessian: F64
    """Mean point-to-plane Hessian per correspondence, 6x6 over a perturbation
    [rotation (rad), translation (m)] of the source in its own frame (gtsam's Pose3
    tangent), so an edge's information in the pose graph is `hessian / sigma^2`."""


def _planar_weakest(rows: F64, axis: F64) -> tuple[float, tuple[float, float, float]]:
    """Like `_weakest`, over the plane across `axis` only (the directions a planar pose
    graph uses)."""
    axis = axis / np.linalg.norm(axis)
    ref = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = ref - axis * (ref @ axis)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    basis = np.stack([e1, e2], axis=1)
    planar = rows @ basis
    values, vectors = np.linalg.eigh(planar.T @ planar / max(planar.shape[0], 1))
    vec = basis @ vectors[:, 0]
    vec = vec if vec[int(np.argmax(np.abs(vec)))] >= 0 else -vec
    return max(float(values[0]), 0.0), (float(vec[0]), float(vec[1]), float(vec[2]))


def evaluate(
    target: Cloud,
    source: Cloud,
    target_from_source: F64,
    distance_m: float,
    threads: int,
    planar_axis: F64 | None = None,
) -> Fit:
    """Overlap, point-to-plane RMSE and conditioning of `source` moved by `target_from_source`."""
    if source.size == 0 or target.size == 0:
        return Fit(0.0, math.inf, _NO_CONDITIONING, 0, np.zeros((6, 6)))
    moved = se3.apply(target_from_source, source.points_m)
    idx, sq = target.tree.batch_nearest_neighbor_search(moved, num_threads=threads)
    idx = np.asarray(idx, dtype=np.int64)
    dist = np.sqrt(np.asarray(sq, dtype=np.float64))
    inlier = dist <= distance_m
    overlap = float(inlier.mean())
    normals = target.normals[idx[inlier]]
    has_normal = np.linalg.norm(normals, axis=1) > 0.5
    if has_normal.sum() < 6:
        return Fit(overlap, math.inf, _NO_CONDITIONING, 0, np.zeros((6, 6)))
    normals = normals[has_normal]
    matched = target.points_m[idx[inlier][has_normal]]
    residual = np.einsum("ij,ij->i", moved[inlier][has_normal] - matched, normals)
    # Jacobian of each residual w.r.t. a body-frame perturbation of the source pose.
    points = source.points_m[inlier][has_normal]
    normals_src = normals @ target_from_source[:3, :3]  # rows: R^T n
    jacobian = np.hstack([np.cross(points, normals_src), normals_src])
    hessian = jacobian.T @ jacobian / jacobian.shape[0]
    lever_len = np.maximum(np.linalg.norm(points, axis=1, keepdims=True), 1e-6)
    if planar_axis is None:
        t_info, t_dir = _weakest(normals_src)
        r_info, r_axis = _weakest(jacobian[:, :3] / lever_len)
    else:
        # Planar motion: translation across the axis, rotation about it only.
        t_info, t_dir = _planar_weakest(normals_src, planar_axis)
        unit = planar_axis / np.linalg.norm(planar_axis)
        r_info = float(np.mean(((jacobian[:, :3] / lever_len) @ unit) ** 2))
        r_axis = (float(unit[0]), float(unit[1]), float(unit[2]))
    return Fit(
        overlap,
        float(np.sqrt(np.mean(residual**2))),
        Conditioning(t_info, r_info, t_dir, r_axis),
        int(jacobian.shape[0]),
        hessian,
    )


@dataclass(frozen=True)
class Alignment:
    """One registration with its before/after quality and the accept/reject verdict."""

    target_from_source: F64
    converged: bool
    iterations: int
    before: Fit
    after: Fit
    accepted: bool
    reason: str | None
    expected_overlap: float | None = None
    """Overlap the two views allow at the seed pose (None: not judged relative to it)."""


def gicp(
    target: Cloud,
    source: Cloud,
    initial: F64,
    max_correspondence_m: float,
    threads: int,
    max_iterations: int,
    **tolerances: float,
) -> Any:
    """One small_gicp GICP run of `source` onto `target` from `initial` (its raw result)."""
    return backend().align(
        target.gicp,
        source.gicp,
        target.tree,
        init_T_target_source=initial,
        registration_type="GICP",
        max_correspondence_distance=max_correspondence_m,
        num_threads=threads,
        max_iterations=max_iterations,
        **tolerances,
    )


def visible_fraction(
    target: Cloud,
    source: Cloud,
    target_from_source: F64,
    *,
    bin_deg: tuple[float, float] = (2.0, 4.0),
) -> float:
    """Share of the source the target's view could hold, with the source at the given pose.

    Both clouds are in their sensor frames, so the target's field of view is the set of
    (azimuth, elevation) cells its points occupy, each out to its farthest return. A moved
    source point inside an occupied cell and not behind the target's farthest return there
    could overlap the target; the rest (outside the target's view, or occluded) cannot.
    This is the overlap "the geometry of the two stops allows" that an alignment's own
    overlap is compared with.
    """
    if source.size == 0 or target.size == 0:
        return 0.0
    az_bin, el_bin = (math.radians(v) for v in bin_deg)

    def cells(points: F64) -> tuple[NDArray[np.int64], F64]:
        rng = np.linalg.norm(points, axis=1)
        az = np.arctan2(points[:, 1], points[:, 0])
        el = np.arcsin(np.clip(points[:, 2] / np.maximum(rng, 1e-9), -1.0, 1.0))
        ia = np.floor((az + math.pi) / az_bin).astype(np.int64)
        ie = np.floor((el + math.pi / 2.0) / el_bin).astype(np.int64)
        return ia * 1000 + ie, rng

    t_cell, t_rng = cells(target.points_m)
    order = np.argsort(t_cell)
    t_cell, t_rng = t_cell[order], t_rng[order]
    keys, first = np.unique(t_cell, return_index=True)
    far = np.maximum.reduceat(t_rng, first)
    s_cell, s_rng = cells(se3.apply(target_from_source, source.points_m))
    pos = np.clip(np.searchsorted(keys, s_cell), 0, keys.size - 1)
    seen = (keys[pos] == s_cell) & (s_rng <= far[pos] * 1.05 + 0.5)
    return float(seen.mean())


def _verdict(after: Fit, limits: AlignmentLimits, expected_overlap: float | None) -> str | None:
    """Why an alignment is rejected (None: accepted): error and conditioning first,
    overlap against what the views allow (or the absolute floor alone)."""
    cond = after.conditioning
    floor = limits.min_overlap
    if expected_overlap is not None:
        floor = max(floor, limits.min_overlap_ratio * expected_overlap)
    if after.overlap < floor:
        if expected_overlap is None or floor == limits.min_overlap:
            return f"overlap {after.overlap:.0%} < {limits.min_overlap:.0%}"
        return (
            f"overlap {after.overlap:.0%} < {limits.min_overlap_ratio:.0%} of the "
            f"{expected_overlap:.0%} the two views allow"
        )
    if after.rmse_m > limits.max_rmse_m:
        return f"error {after.rmse_m * 100:.1f} cm > {limits.max_rmse_m * 100:.1f} cm"
    if cond.translation_information < limits.min_translation_information:
        t = cond.weakest_translation
        return (
            f"degenerate: translation along ({t[0]:.2f}, {t[1]:.2f}, {t[2]:.2f}) barely "
            f"constrained ({cond.translation_information:.4f} < "
            f"{limits.min_translation_information})"
        )
    if cond.rotation_information < limits.min_rotation_information:
        r = cond.weakest_rotation_axis
        return (
            f"degenerate: rotation about ({r[0]:.2f}, {r[1]:.2f}, {r[2]:.2f}) barely "
            f"constrained ({cond.rotation_information:.4f} < {limits.min_rotation_information})"
        )
    return None


def align(
    target: Cloud,
    source: Cloud,
    initial: F64,
    limits: AlignmentLimits,
    *,
    max_iterations: int,
    threads: int,
    expected_overlap: float | None = None,
    planar_axis: F64 | None = None,
) -> Alignment:
    """Coarse-to-fine GICP from `initial`, then the error, degeneracy and overlap tests.

    `expected_overlap` (e.g. `visible_fraction` at the coarse pose) makes the overlap test
    relative to what the two views can share; without it only the absolute floor applies.
    With `planar_axis` (the LiDAR's up, for a planar pose graph) conditioning is judged on
    the planar directions only: roll and pitch between stops are not estimated there.
    """
    before = evaluate(target, source, initial, limits.overlap_distance_m, threads)
    transform = np.asarray(initial, dtype=np.float64)
    converged, iterations = False, 0
    result: Any = None
    for max_corr in limits.correspondence_stages_m:
        result = gicp(
            target,
            source,
            transform,
            max_corr,
            threads,
            max_iterations,
            rotation_epsilon=_ROTATION_EPS_RAD,
            translation_epsilon=_TRANSLATION_EPS_M,
        )
        transform = np.asarray(result.T_target_source, dtype=np.float64)
        converged = bool(result.converged)
        iterations += int(result.iterations)
    after = evaluate(target, source, transform, limits.overlap_distance_m, threads, planar_axis)
    reason = _verdict(after, limits, expected_overlap)
    return Alignment(
        target_from_source=transform,
        converged=converged,
        iterations=iterations,
        before=before,
        after=after,
        accepted=reason is None,
        reason=reason,
        expected_overlap=expected_overlap,
    )


def yaw_search(
    pairs: list[tuple[Cloud, Cloud, F64]],
    *,
    step_deg: float,
    max_step_deg: float,
    max_correspondence_m: float,
    overlap_distance_m: float,
    threads: int,
) -> tuple[float, list[tuple[F64, Fit]]]:
    """Vehicle turn between two stops by a search over yaw hypotheses, scored jointly.

    `pairs` holds, per LiDAR, (scan at the first stop, scan at the second, recorded
    base_from_lidar). The turn is unknown but the same for every LiDAR, and GICP only
    converges from a few degrees away, so each hypothesis seeds a coarse GICP per LiDAR
    (rotation about the base's z axis, carried into the LiDAR frame by the recorded
    extrinsic) and the hypothesis with the largest summed overlap wins: a LiDAR facing a
    symmetric view cannot pick a wrong turn on its own. Returns (yaw_deg, per-LiDAR
    (first_from_second, coarse fit)).
    """
    best: tuple[float, float, list[tuple[F64, Fit]]] = (0.0, -1.0, [])
    n = max(1, math.floor(max_step_deg / step_deg))
    for k in range(-n, n + 1):
        yaw_deg = k * step_deg
        if yaw_deg >= 180.0 and -n * step_deg <= -180.0:
            continue  # +180 and -180 are the same hypothesis
        turn = np.eye(4)
        turn[:3, :3] = se3.rot_z(math.radians(yaw_deg))
        found: list[tuple[F64, Fit]] = []
        for target, source, base_from_lidar in pairs:
            init = se3.invert(base_from_lidar) @ turn @ base_from_lidar
            result = gicp(target, source, init, max_correspondence_m, threads, 20)
            transform = np.asarray(result.T_target_source, dtype=np.float64)
            found.append(
                (transform, evaluate(target, source, transform, overlap_distance_m, threads))
            )
        score = sum(fit.overlap for _, fit in found)
        if score > best[1]:
            best = (yaw_deg, score, found)
    return best[0], best[2]
