"""Ground removal for base-frame clouds: flat ground overlaps itself at any turn and fills a
top view, so the coarse turn search and the top view use only what stands on it."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]

_GROUND_BAND_M = 0.3
_GROUND_KEEP_M = 0.2


def off_ground(points_m: F64) -> NDArray[np.bool_]:
    """Mask of the points of a base-frame cloud (z up) that are not on the ground plane.

    The plane is fitted (least squares, then twice more on its inliers) to the low points
    -- within a band above the 5th height percentile -- and points within 0.2 m of it are
    on the ground. Fewer than 50 points: all are kept (too few to fit a plane).
    """
    if points_m.shape[0] < 50:
        return np.ones(points_m.shape[0], dtype=bool)
    z = points_m[:, 2]
    low = points_m[z < float(np.percentile(z, 5)) + _GROUND_BAND_M]
    design = np.c_[points_m[:, :2], np.ones(points_m.shape[0])]
    low_design = np.c_[low[:, :2], np.ones(low.shape[0])]
    coef: F64 = np.asarray(np.linalg.lstsq(low_design, low[:, 2], rcond=None)[0], dtype=np.float64)
    for _ in range(2):
        resid = z - design @ coef
        inl = np.abs(resid) < _GROUND_KEEP_M
        if inl.sum() < 3:
            break
        coef = np.asarray(np.linalg.lstsq(design[inl], z[inl], rcond=None)[0], dtype=np.float64)
    return np.asarray(np.abs(z - design @ coef) > _GROUND_KEEP_M)


def remove_ground(points_m: F64) -> F64:
    """Points of a base-frame cloud that are not on the ground plane (all of them when
    fewer than 50 would be left). Flat ground overlaps itself at any turn, so only the
    rest can tell turns apart."""
    keep = off_ground(points_m)
    return points_m[keep] if keep.sum() >= 50 else points_m


def ground_plane(points_m: F64, up: F64) -> tuple[F64, float, int] | None:
    """The ground plane in a LiDAR's own frame: (unit normal along `up`, offset d with
    n.p + d = 0, inliers), or None when fewer than 200 points lie on it.

    Seeded by the lowest points along `up` (within a band above their 5th percentile),
    then refitted three times by total least squares on the points within 5 cm of it."""
    u = up / np.linalg.norm(up)
    height = points_m @ u
    inliers = points_m[height < float(np.percentile(height, 5)) + _GROUND_BAND_M]
    normal, offset = u, -float(np.median(inliers @ u)) if inliers.size else 0.0
    for _ in range(3):
        near = np.abs(points_m @ normal + offset) < 0.05
        if int(near.sum()) < 200:
            return None
        inliers = points_m[near]
        centre = inliers.mean(axis=0)
        _s, _v, vt = np.linalg.svd(inliers - centre, full_matrices=False)
        normal = vt[2] if float(vt[2] @ u) >= 0 else -vt[2]
        offset = -float(normal @ centre)
    return np.asarray(normal, dtype=np.float64), offset, int(inliers.shape[0])
