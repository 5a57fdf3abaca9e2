"""Map-to-map alignment (calib.registration) on real LiDAR scans with a known transform.

No public two-LiDAR recording with a published extrinsic is reachable from here (the
machine has no network; PJLab SensorsCalibration's Pandar64 + QT scans are binary files
the project does not hold), so each real scan of the nebula recordings stands in for two
LiDARs: its even and odd points (interleaved, so no point is in both) are the two
"sensors", the odd half is moved by a known extrinsic into its own frame, and the map-to-
map GICP, seeded 0.5 deg / 5 cm off as a recorded extrinsic would be, must land on the
known one. The scene, the beam pattern and the range noise are the real sensor's.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from syncaudit.calib import se3
from syncaudit.calib.alignment.registration import align, prepare
from syncaudit.calib.settings import CalibConfig

pytest.importorskip("small_gicp")

SCANS = ("hesai_40p", "hesai_xt32", "velodyne_vlp32")
TRUE = se3.make_transform(
    se3.rpy_to_matrix(math.radians(0.8), math.radians(-1.5), math.radians(178.0)), (-2.8, 0.1, -0.1)
)
"""reference_from_other: a rear LiDAR 2.8 m behind, turned round, slightly tilted."""
SEED_ERROR = se3.make_transform(se3.rpy_to_matrix(0.0, 0.0, math.radians(0.5)), (0.05, 0.0, 0.0))


def _pcd_xyz(path: Path) -> NDArray[np.float64]:
    """Binary PCD v0.7 with float32 x y z (the nebula test resources)."""
    raw = path.read_bytes()
    end = raw.index(b"DATA binary\n") + len(b"DATA binary\n")
    pts = np.frombuffer(raw, "<f4", offset=end).reshape(-1, 3).astype(np.float64)
    keep = np.isfinite(pts).all(axis=1) & (np.linalg.norm(pts, axis=1) > 0.5)
    return np.asarray(pts[keep], dtype=np.float64)


@pytest.mark.parametrize("folder", SCANS)
def test_real_scan_halves_align_to_the_known_extrinsic(lidar_data: Path, folder: str) -> None:
    (pcd,) = sorted((lidar_data / folder).glob("*.pcd"))
    points = _pcd_xyz(pcd)
    reference, other = points[0::2], se3.apply(se3.invert(TRUE), points[1::2])
    config = CalibConfig()
    mc, reg = config.map_to_map, config.registration
    target = prepare(reference, mc.voxel_m, mc.neighbours, reg.num_threads)
    source = prepare(other, mc.voxel_m, mc.neighbours, reg.num_threads)
    result = align(
        target,
        source,
        TRUE @ SEED_ERROR,
        mc.limits,
        max_iterations=reg.max_iterations,
        threads=reg.num_threads,
    )
    assert result.accepted, result.reason
    rot_deg, trans_m = se3.transform_difference(TRUE, result.target_from_source)
    print(f"{folder}: {points.shape[0]} points, {rot_deg:.4f} deg, {trans_m * 100:.3f} cm")
    assert rot_deg < 0.05 and trans_m * 100.0 < 0.5, (folder, rot_deg, trans_m * 100.0)
