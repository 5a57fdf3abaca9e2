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
