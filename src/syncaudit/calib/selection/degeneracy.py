"""Refusing a degenerate scene (a corridor, ground plus one wall) before any registration."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib import extrinsics as extr
from syncaudit.calib.alignment.registration import prepare
from syncaudit.calib.result import DegeneracyOut
from syncaudit.calib.settings import CalibConfig
from syncaudit.calib.state import LidarState, vehicle_points

F64 = NDArray[np.float64]


_DEGENERATE_INFORMATION = 0.02
"""A scene whose merged normals leave a direction with less than this mean squared
constraint at most stops (a corridor, ground plus one wall) cannot be calibrated.
Measured on the simulator's sessions: ground plus one wall and corridors 0.0005-0.007
(16-beam normals are the noisiest), every yard case (bumper mounts, 16 beams) 0.07 or more."""


def degenerate_scene(
    lidars: list[LidarState], recorded: extr.RecordedExtrinsics, config: CalibConfig
) -> tuple[str, DegeneracyOut] | None:
    """Why the scene itself cannot constrain an alignment, and its free direction; or None.

    Per stop, the normals of all LiDARs' points (base frame) give sum(n n^T); a direction
    with (almost) no constraint -- along a corridor, along a lone wall over flat ground --
    makes every alignment slide. Refused before any registration when most stops show it;
    the direction named is the weakest stop's, in the base frame at that stop.
    """
    reg = config.registration
    order = sorted({k for lidar in lidars for k in lidar.stop_scan})
    free: list[tuple[float, F64, int]] = []
    for k in order:
        cloud = prepare(
            vehicle_points(lidars, k, recorded), reg.coarse_voxel_m, 20, reg.num_threads
        )
        normals = cloud.normals[np.linalg.norm(cloud.normals, axis=1) > 0.5]
        if normals.shape[0] < 10:
            continue
        values, vectors = np.linalg.eigh(normals.T @ normals / normals.shape[0])
        free.append((float(values[0]), vectors[:, 0], k))
    weak = [w for w in free if w[0] < _DEGENERATE_INFORMATION]
    if not free or len(weak) * 2 <= len(free):
        return None
    value, direction, stop = min(weak, key=lambda w: w[0])
    direction = direction if direction[int(np.argmax(np.abs(direction)))] >= 0 else -direction
    x, y, z = (float(v) for v in direction)
    reason = (
        f"degenerate scene: at {len(weak)} of {len(free)} stops nothing constrains translation "
        f"along ({x:.2f}, {y:.2f}, {z:.2f}) in {recorded.base_frame} (information {value:.4f} "
        f"< {_DEGENERATE_INFORMATION}): a corridor or a lone wall over flat ground; "
        "calibrate where the LiDARs see structure facing several directions"
    )
    return reason, DegeneracyOut(
        kind="translation",
        direction=(x, y, z),
        frame=f"{recorded.base_frame} at stop {stop}",
        information=value,
        limit=_DEGENERATE_INFORMATION,
    )
