"""Rolling shutter: each row exposes `row_time` after the one above it.

The exposure start a log gives is the top row's; row r's middle of exposure is that start
+ r * row_time + t5 / 2, so its error against the LiDAR is the frame's error + r * row_time.
The LiDAR meets the camera's azimuth centre on every row at once (a vertical line of the
image); which row matters is the rig's `lidar_row` (default the centre row).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from syncaudit.analysis.stats import error_mean
from syncaudit.rig import CameraConfig

PROFILE_POINTS = 9
"""Rows the error-against-row profile is given at (top to bottom, evenly)."""


@dataclass(frozen=True, slots=True)
class RowTiming:
    """One camera's rolling-shutter geometry."""

    rows: int
    row_time_ns: float
    target_row: int

    @property
    def readout_ns(self) -> float:
        """Top row's start to the last row's start plus one row (rows x row time)."""
        return self.rows * self.row_time_ns


def row_timing(camera: CameraConfig, rows_from_log: int | None = None) -> RowTiming | None:
    """The camera's rows and row time from the rig (rows from the log where the rig has
    none: CameraInfo or Image height); None for a global shutter (no readout given)."""
    rows = camera.rows or rows_from_log
    if camera.row_time_us is not None and rows:
        row_time = camera.row_time_us * 1e3
    elif camera.readout_us is not None and rows:
        row_time = camera.readout_us * 1e3 / rows
    else:
        return None
    target = camera.lidar_row if camera.lidar_row is not None else rows // 2
    return RowTiming(rows, row_time, min(target, rows - 1))


def row_offset_ns(timing: RowTiming, row: int) -> float:
    """How much later row `row` exposes than the top row."""
    return row * timing.row_time_ns


def per_row(errors_ns: NDArray[np.float64], timing: RowTiming) -> dict[str, Any]:
    """Signed and Eq. 5 error at the top, target and bottom rows, and a profile by row."""
    e = errors_ns[np.isfinite(errors_ns)]

    def at(row: int) -> dict[str, Any]:
        shifted = e + row_offset_ns(timing, row)
        return {
            "row": row,
            "error_signed_mean_us": _us(float(shifted.mean()) if shifted.size else math.nan),
            "error_mean_us": _us(error_mean(np.abs(shifted))),
        }

    rows = np.linspace(0, timing.rows - 1, PROFILE_POINTS).round().astype(int)
    return {
        "rows": timing.rows,
        "row_time_us": round(timing.row_time_ns / 1e3, 4),
        "readout_us": round(timing.readout_ns / 1e3, 3),
        "target_row": timing.target_row,
        "top": at(0),
        "target": at(timing.target_row),
        "bottom": at(timing.rows - 1),
        "profile": [at(int(r)) for r in rows],
    }


def _us(ns: float) -> float | None:
    return round(ns / 1e3, 3) if math.isfinite(ns) else None
