"""Point clouds of a simulated LiDAR in the field conventions real drivers write.

The points come from the same firing times the packets are written from: each delivered
packet's blocks, one point per beam, beam k firing FIRING_STEP_NS * k after its block's
first firing, at the head's exact azimuth then (the simulator's rotation model). What a
convention changes is only how the time and the azimuth are stored (see docs/clouds.md);
this module writes them on its own, without the reader it is checked against.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from syncaudit.writers.log_writer import LogWriter

__all__ = ["CLOUD_CONVENTIONS", "CloudConvention", "CloudPoints", "cloud_message"]

CloudConvention = Literal["velodyne", "ouster", "nebula", "livox", "hesai", "absolute_ns"]
CLOUD_CONVENTIONS: tuple[CloudConvention, ...] = (
    "velodyne",
    "ouster",
    "nebula",
    "livox",
    "hesai",
    "absolute_ns",
)
FIRING_STEP_NS = 2_304
"""Time between two beams of a block (VLP-16's firing interval)."""
RANGE_M = 10.0

# PointField datatypes (sensor_msgs/PointField) and 9 for uint64.
_F4, _F8, _U1, _U2, _U4, _U8 = 7, 8, 2, 4, 6, 9
_Field = tuple[str, int, int, str]  # name, offset, datatype, numpy type

_LAYOUTS: dict[CloudConvention, tuple[list[_Field], int]] = {
    # ros-drivers/velodyne PointcloudXYZIRT (PointCloud2Modifier packs the fields): time
    # float32 s at byte 18 of 22, unaligned, as `/velodyne_points` shows.
    "velodyne": (
        [
            ("x", 0, _F4, "f4"),
            ("y", 4, _F4, "f4"),
            ("z", 8, _F4, "f4"),
            ("intensity", 12, _F4, "f4"),
            ("ring", 16, _U2, "u2"),
            ("time", 18, _F4, "f4"),
        ],
        22,
    ),
    # ouster-ros PointXYZIRT-like: t uint32 ns, 48-byte padded point, organized.
    "ouster": (
        [
            ("x", 0, _F4, "f4"),
            ("y", 4, _F4, "f4"),
            ("z", 8, _F4, "f4"),
            ("intensity", 16, _F4, "f4"),
            ("t", 20, _U4, "u4"),
            ("reflectivity", 24, _U2, "u2"),
            ("ring", 26, _U2, "u2"),
            ("ambient", 28, _U2, "u2"),
            ("range", 32, _U4, "u4"),
        ],
        48,
    ),
    # tier4/nebula PointXYZIRCAEDT.
    "nebula": (
        [
            ("x", 0, _F4, "f4"),
            ("y", 4, _F4, "f4"),
            ("z", 8, _F4, "f4"),
            ("intensity", 12, _U1, "u1"),
            ("return_type", 13, _U1, "u1"),
            ("channel", 14, _U2, "u2"),
            ("azimuth", 16, _F4, "f4"),
            ("elevation", 20, _F4, "f4"),
            ("distance", 24, _F4, "f4"),
            ("time_stamp", 28, _U4, "u4"),
        ],
        32,
    ),
    # Livox-style: offset_time uint32 ns after the stamp.
    "livox": (
        [
            ("x", 0, _F4, "f4"),
            ("y", 4, _F4, "f4"),
            ("z", 8, _F4, "f4"),
            ("intensity", 12, _F4, "f4"),
            ("tag", 16, _U1, "u1"),
            ("line", 17, _U1, "u1"),
            ("offset_time", 20, _U4, "u4"),
        ],
        24,
    ),
    # HesaiLidar_ROS_2.0 (source_driver_ros2.hpp ToRosMsg): fields packed one after the
    # other, so the float64 timestamp (absolute s) sits unaligned at byte 18 of 26.
    "hesai": (
        [
            ("x", 0, _F4, "f4"),
            ("y", 4, _F4, "f4"),
            ("z", 8, _F4, "f4"),
            ("intensity", 12, _F4, "f4"),
            ("ring", 16, _U2, "u2"),
            ("timestamp", 18, _F8, "f8"),
        ],
        26,
    ),
    "absolute_ns": (
        [
            ("x", 0, _F4, "f4"),
            ("y", 4, _F4, "f4"),
            ("z", 8, _F4, "f4"),
            ("ring", 12, _U2, "u2"),
            ("timestamp", 16, _U8, "u8"),
        ],
        24,
    ),
}


@dataclass(frozen=True, slots=True)
class CloudPoints:
    """The points of one cloud, (beams, columns): sensor time (ns) and packet azimuth (deg)."""

    time_ns: NDArray[np.int64]
    azimuth_deg: NDArray[np.float64]


def cloud_points(
    block_sensor_ns: NDArray[np.int64],
    beams: int,
    azimuth_at: Callable[[NDArray[np.int64]], NDArray[np.float64]],
) -> CloudPoints:
    """(beams, blocks) points of consecutive blocks: each beam's firing time and azimuth."""
    times = block_sensor_ns.reshape(1, -1) + FIRING_STEP_NS * np.arange(beams)[:, None]
    return CloudPoints(times.astype(np.int64), azimuth_at(times))


def cloud_message(
    writer: LogWriter,
    convention: CloudConvention,
    points: CloudPoints,
    frame_id: str,
    x_axis_azimuth_deg: float,
    *,
    stamp: Literal["first", "last"] = "first",
    bigendian: bool = False,
) -> tuple[int, Any]:
    """(header stamp, PointCloud2 message) of `points` in `convention`; ouster's is
    organized (rows = beams), the others list the points in firing order."""
    fields, step = _LAYOUTS[convention]
    order = ">" if bigendian else "<"
    dtype = np.dtype(
        {
            "names": [f[0] for f in fields],
            "formats": [order + f[3] for f in fields],
            "offsets": [f[1] for f in fields],
            "itemsize": step,
        }
    )
    organized = convention == "ouster"
    times = points.time_ns if organized else points.time_ns.T
    azimuth = points.azimuth_deg if organized else points.azimuth_deg.T
    stamp_ns = int(times.min()) if stamp == "first" else int(times.max())
    grid: NDArray[Any] = np.zeros(times.shape, dtype=dtype)
    clockwise = np.radians(azimuth - x_axis_azimuth_deg)
    grid["x"] = RANGE_M * np.cos(clockwise)
    grid["y"] = -RANGE_M * np.sin(clockwise)
    relative = times - stamp_ns
    if convention == "velodyne":
        grid["time"] = relative / 1e9
    elif convention == "ouster":
        grid["t"] = relative
    elif convention == "nebula":
        grid["time_stamp"] = relative
        grid["azimuth"] = np.radians(azimuth % 360.0)
    elif convention == "livox":
        grid["offset_time"] = relative
    elif convention == "hesai":
        grid["timestamp"] = times / 1e9
    else:
        grid["timestamp"] = times
    if not organized:
        grid = grid.reshape(1, -1)
    height, width = int(grid.shape[0]), int(grid.shape[1])
    msg_fields = [
        writer.new_msg("sensor_msgs/msg/PointField", name=n, offset=o, datatype=d, count=1)
        for n, o, d, _ in fields
    ]
    msg = writer.new_msg(
        "sensor_msgs/msg/PointCloud2",
        header=writer.header(stamp_ns, frame_id),
        height=height,
        width=width,
        fields=msg_fields,
        is_bigendian=bigendian,
        point_step=step,
        row_step=step * width,
        data=np.ascontiguousarray(grid).view(np.uint8).reshape(-1),
        is_dense=True,
    )
    return stamp_ns, msg
