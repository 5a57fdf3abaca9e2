"""The vehicle's up in the reference LiDAR's frame, for the joint graph's planar prior.

Two estimates exist: the turn axis (the rotation axes of the LiDAR's own stop-to-stop
alignments) and the ground plane's normal (fitted to thousands of ground points per stop).
A vehicle turning on flat ground turns about the ground's normal, so both estimate one
axis; which is firmer depends on the data. Where the scans hold much structure the
alignments' axes agree to a few thousandths of a degree and the turn axis is the better
one (the ground fit can be biased by ~0.02 deg by what stands on it: measured on a 32-beam
drive, turn axis 0.005 deg from the truth, ground 0.019). A 16-beam roof LiDAR in a parking
lot sees the parked cars in two or three rings: its alignments' axes scatter by a median
0.6 deg and their mean sat 0.35 deg from the truth while the ground normal was 0.0001 deg
from it; the planar prior about that turn axis tilted the joint extrinsic by 0.43 deg.

The rule: the turn axis unless its standard error (robust spread of the alignments' axes
about it over the square root of their count) exceeds the ground's flatness floor
(`GROUND_FLOOR_DEG`), then the ground normal -- and only when that normal was fitted at
enough stops and agrees across them within the floor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib import se3
from syncaudit.calib.graph import posegraph

F64 = NDArray[np.float64]

GROUND_FLOOR_DEG = 0.05
"""Smallest 1-sigma of a LiDAR's ground plane: ground in a parking lot or yard is not
flat to better than this."""
_MIN_TURN_DEG = 5.0
"""Alignments turning less than this give no usable axis (as in `posegraph.turn_axis`)."""
_MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True)
class VehicleUp:
    """The chosen up, where it came from, and the figures that chose it."""

    axis: F64
    source: str
    """"turn axis", "ground plane" or "recorded" (neither was available)."""
    turn_axis_error_deg: float | None
    """Standard error of the turn axis from its alignments' spread (None: none turned)."""
    ground_spread_deg: float | None
    """Median angle of the per-stop ground normals from their median (None: no ground)."""


def axis_standard_error_deg(edges: list[posegraph.Edge], axis: F64) -> float | None:
    """Robust standard error (deg) of a turn axis from its alignments' rotation axes."""
    unit = axis / np.linalg.norm(axis)
    angles = []
    for edge in edges:
        rotvec = se3.log_so3(edge.first_from_second[:3, :3])
        norm = float(np.linalg.norm(rotvec))
        if norm < math.radians(_MIN_TURN_DEG):
            continue
        own = rotvec / norm * (1.0 if float(rotvec @ unit) >= 0 else -1.0)
        angles.append(math.degrees(math.acos(float(np.clip(own @ unit, -1.0, 1.0)))))
    if len(angles) < 2:
        return None
    return _MAD_TO_SIGMA * float(np.median(angles)) / math.sqrt(len(angles))


def vehicle_up(
    turn_axis: F64 | None,
    edges: list[posegraph.Edge],
    ground_normal: F64 | None,
    ground_spread_deg: float | None,
    recorded_up: F64,
) -> VehicleUp:
    """The planar prior's axis by the rule of the module docstring."""
    error = None if turn_axis is None else axis_standard_error_deg(edges, turn_axis)
    flat = ground_normal is not None and (ground_spread_deg or 0.0) <= GROUND_FLOOR_DEG
    loose = turn_axis is None or (error or 0.0) > GROUND_FLOOR_DEG
    if ground_normal is not None and flat and loose:
        return VehicleUp(ground_normal, "ground plane", error, ground_spread_deg)
    if turn_axis is not None:
        return VehicleUp(turn_axis, "turn axis", error, ground_spread_deg)
    return VehicleUp(recorded_up, "recorded", error, ground_spread_deg)
