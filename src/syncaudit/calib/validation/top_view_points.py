"""A LiDAR's local map seen from above: each used stop's points placed by its estimated pose.

For the report's map coloured by stop: when the poses are right, a wall seen from two
stops draws one line; a wrong pose draws it twice. Points are decimated to one per
`cell_m` square per stop (the first point of the scan in each cell, so every point drawn
is a measured one, never an average across a corner) and rounded to 1 cm, which keeps a
12-stop session to a few hundred KB of JSON.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib import se3
from syncaudit.calib.alignment.ground import off_ground
from syncaudit.calib.result import StopPointsOut, TopViewOut

F64 = NDArray[np.float64]

TOP_VIEW_CELL_M = 0.2
"""Side of the square cell one top-view point stands for."""
_RESOLUTION_M = 0.01
"""x/y are rounded to 1 cm (far below the cell size; it only shortens the JSON)."""


def decimate_xy(xy_m: F64, cell_m: float) -> F64:
    """One point per `cell_m` x `cell_m` square (cells aligned on multiples of `cell_m`),
    rounded to 1 cm: the first point (in input order) of each occupied cell, in that
    order. Cells are taken on the rounded centimetres, in integers, so two points drawn
    never share a cell."""
    if xy_m.shape[0] == 0:
        return np.zeros((0, 2))
    xy_cm = np.round(xy_m / _RESOLUTION_M).astype(np.int64)
    cells = np.floor_divide(xy_cm, max(1, round(cell_m / _RESOLUTION_M)))
    _unique, first = np.unique(cells, axis=0, return_index=True)
    return np.asarray(xy_cm[np.sort(first)] * _RESOLUTION_M, dtype=np.float64)


def top_view(
    scans_m: Mapping[int, NDArray[np.floating[Any]]],
    anchor_from_stop: dict[int, F64],
    base_from_lidar: F64,
    frame: str,
    *,
    cell_m: float = TOP_VIEW_CELL_M,
) -> TopViewOut:
    """Top view of one LiDAR's used stops in the base frame at the anchor stop.

    `scans_m` are the stops' static scans in the LiDAR's frame, `anchor_from_stop` the
    LiDAR's pose at each stop relative to its pose at the anchor (from its pose graph),
    `base_from_lidar` the mount used to place the map on the vehicle. The ground (fitted
    per stop in the base frame) is left out: it covers every cell around the vehicle and
    says nothing about whether the poses are right.
    """
    stops = []
    for stop in sorted(anchor_from_stop):
        placed = se3.apply(base_from_lidar @ anchor_from_stop[stop], scans_m[stop])
        # The ground is fitted in the stop's own base frame (z up wherever the vehicle stood).
        local = se3.apply(base_from_lidar, scans_m[stop])
        keep = off_ground(local)
        xy = np.round(decimate_xy(placed[keep, :2], cell_m), 2)
        stops.append(StopPointsOut(stop=stop, x_m=xy[:, 0].tolist(), y_m=xy[:, 1].tolist()))
    return TopViewOut(frame=frame, cell_m=cell_m, stops=stops)
