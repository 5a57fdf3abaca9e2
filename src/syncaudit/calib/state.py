"""Working state of each LiDAR through the calibration: its scans and what each stage found."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib import extrinsics as extr
from syncaudit.calib import se3
from syncaudit.calib.alignment.deskew import SweepTimes
from syncaudit.calib.alignment.registration import Alignment, Cloud
from syncaudit.calib.graph import posegraph
from syncaudit.calib.result import MovingScansOut, PairOut, PoseGraphOut

F64 = NDArray[np.float64]


@dataclass
class SampledScan:
    """A scan kept in memory: points at the finest voxel used (float32), and when each
    azimuth was fired (None: the cloud has no time field) so a moving scan can be deskewed."""

    stamp_ns: int
    points_m: NDArray[np.float32]
    sweep: SweepTimes | None = None


@dataclass
class LidarState:
    """Working state of one LiDAR through the pipeline."""

    topic: str
    frame_id: str
    scans: list[SampledScan]
    up: F64
    stop_scan: dict[int, int] = field(default_factory=dict)
    angles: dict[int, float | None] = field(default_factory=dict)
    chain: dict[int, F64] = field(default_factory=dict)
    dropped: dict[int, str] = field(default_factory=dict)
    kept: list[int] = field(default_factory=list)
    fine: dict[int, Cloud] = field(default_factory=dict)
    hfov_deg: float | None = None
    pairs: list[PairOut] = field(default_factory=list)
    graph: PoseGraphOut | None = None
    graphs: dict[frozenset[int], posegraph.PoseGraphSolution] = field(default_factory=dict)
    used: set[int] = field(default_factory=set)
    map_points: int = 0
    candidates: list[tuple[int, int, float, float]] = field(default_factory=list)
    results: dict[tuple[int, int], Alignment] = field(default_factory=dict)
    turn_axis: F64 | None = None
    reason: str | None = None
    moving: MovingScansOut | None = None


def vehicle_points(lidars: list[LidarState], stop: int, recorded: extr.RecordedExtrinsics) -> F64:
    """All LiDARs' points at one stop in the base frame (recorded extrinsics)."""
    parts = [
        se3.apply(
            recorded.base_from_frame[lidar.frame_id],
            lidar.scans[lidar.stop_scan[stop]].points_m,
        )
        for lidar in lidars
        if stop in lidar.stop_scan
    ]
    return np.concatenate(parts)
