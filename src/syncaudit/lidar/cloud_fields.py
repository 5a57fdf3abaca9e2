"""Which PointCloud2 fields give each point's time and azimuth, and numpy views on them.

Conventions (each checked against the driver's source, see docs/clouds.md):

| field | type | meaning | driver |
| --- | --- | --- | --- |
| `time` | float32 | s after the header stamp | ros-drivers/velodyne PointXYZIRT |
| `t` | uint32 | ns after the header stamp | ouster-ros |
| `time_stamp` | uint32 | ns after the header stamp | tier4/nebula PointXYZIRCAEDT |
| `offset_time` | uint32 | ns after the header stamp | Livox (livox_ros_driver2) |
| `timestamp` | float64 | absolute s | HesaiLidar_ROS_2.0, RoboSense rslidar_sdk |
| `timestamp` | uint64 (datatype 9) | absolute ns | drivers writing integer stamps |

A relative time is measured from the header stamp; a float field holding values beyond
1e6 s is taken as absolute whatever its name. `azimuth` (float32, radians; nebula) is the
vendor's packet azimuth; without it the azimuth is the clockwise angle from the frame's +X
seen from above, `atan2(-y, x)`, plus the packet azimuth of +X (every supported vendor
spins clockwise). Only the needed fields are viewed: strided numpy arrays on the message's
bytes, in the cloud's byte order, whatever the `point_step` padding.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from syncaudit.errors import DecodeError
from syncaudit.lidar.cloud_layout import DATATYPES, UINT64, CloudField, CloudLayout

__all__ = ["TIME_FIELDS", "CloudTime", "field_view", "point_azimuth_deg", "point_times_ns"]

TIME_FIELDS: tuple[str, ...] = ("time", "t", "time_stamp", "offset_time", "timestamp")
"""Field names searched for per-point time, in this order."""
ABSOLUTE_MIN_S = 1e6
"""A time value beyond this (s) is an absolute stamp, not an offset within a revolution."""


@dataclass(frozen=True, slots=True)
class CloudTime:
    """The time field of a cloud and how to read it."""

    name: str
    unit_ns: float
    """Nanoseconds per unit of the stored value (1e9 for seconds)."""


def _dtype(field: CloudField, bigendian: bool) -> np.dtype[Any]:
    order = ">" if bigendian else "<"
    if field.datatype == UINT64:
        return np.dtype(order + "u8")
    kind = DATATYPES.get(field.datatype)
    if kind is None:
        raise DecodeError(f"PointCloud2 field {field.name}: datatype {field.datatype} unknown")
    return np.dtype(order + kind)


def field_view(
    layout: CloudLayout, data: bytes | memoryview, name: str, stride: int = 1
) -> NDArray[Any]:
    """(height, ceil(width / stride)) view of one field of every `stride`-th point of each
    row (no copy), in the cloud's byte order."""
    field = layout.fields[name]
    dtype = _dtype(field, layout.is_bigendian)
    if field.offset + dtype.itemsize > layout.point_step:
        raise DecodeError(
            f"PointCloud2 field {name} at offset {field.offset} overruns point_step "
            f"{layout.point_step}"
        )
    buffer = np.frombuffer(data, dtype=np.uint8, count=layout.data_size, offset=layout.data_offset)
    if layout.n_points == 0:
        return np.empty((layout.height, layout.width), dtype=dtype)
    return np.ndarray(
        (layout.height, -(-layout.width // stride)),
        dtype=dtype,
        buffer=buffer,
        offset=field.offset,
        strides=(layout.row_step, layout.point_step * stride),
    )


def cloud_time(layout: CloudLayout, time_field: str | None = None) -> CloudTime:
    """The time field (the rig's, else the first of TIME_FIELDS present) and its unit."""
    names = (time_field,) if time_field else TIME_FIELDS
    for name in names:
        field = layout.fields.get(name)
        if field is None:
            continue
        floating = field.datatype in (7, 8)
        return CloudTime(name, 1e9 if floating else 1.0)
    wanted = time_field or ", ".join(TIME_FIELDS)
    present = ", ".join(layout.fields) or "none"
    raise DecodeError(f"PointCloud2 has no per-point time field ({wanted}); its fields: {present}")


def point_times_ns(
    layout: CloudLayout, data: bytes | memoryview, time: CloudTime, stride: int = 1
) -> tuple[NDArray[np.float64], int | None]:
    """Time of each (`stride`-th) point in ns as float64 after an integer base, and that
    base: None where the times are relative (to the header stamp), else the absolute time
    (ns) they count from, chosen near them so float64 keeps them to the nanosecond."""
    raw = field_view(layout, data, time.name, stride)
    if raw.dtype.kind in "iu":
        finite = raw.reshape(-1)
        if not finite.size or int(np.max(finite)) * time.unit_ns / 1e9 <= ABSOLUTE_MIN_S:
            return raw.astype(np.float64) * time.unit_ns, None
        base = int(np.min(finite))
        shifted = (raw.astype(np.int64) - base).astype(np.float64) * time.unit_ns
        return shifted, round(base * time.unit_ns)
    values = raw.astype(np.float64)
    finite = values[np.isfinite(values)]
    if not finite.size or float(np.max(np.abs(finite))) * time.unit_ns / 1e9 <= ABSOLUTE_MIN_S:
        return values * time.unit_ns, None
    base_units = math.floor(float(finite.min()))
    return (values - base_units) * time.unit_ns, round(base_units * time.unit_ns)


def point_azimuth_deg(
    layout: CloudLayout,
    data: bytes | memoryview,
    x_axis_azimuth_deg: float,
    clockwise: bool = True,
    stride: int = 1,
) -> NDArray[np.float64]:
    """Packet azimuth of each (`stride`-th) point in degrees, NaN where a point has none
    (NaN or zero x/y): the `azimuth` field where there is one, else from x and y."""
    if "azimuth" in layout.fields:
        raw = field_view(layout, data, "azimuth", stride).astype(np.float64)
        finite = raw[np.isfinite(raw)]
        in_radians = not finite.size or float(np.max(np.abs(finite))) <= 2 * np.pi + 1e-3
        degrees = np.degrees(raw) if in_radians else raw
        out: NDArray[np.float64] = degrees % 360.0
        return out
    if "x" not in layout.fields or "y" not in layout.fields:
        raise DecodeError("PointCloud2 has neither an azimuth field nor x and y")
    x = field_view(layout, data, "x", stride)
    y = field_view(layout, data, "y", stride)
    # In the fields' own float type (float32: 1e-7 rad, 0.02 us at 600 rpm), then degrees.
    angle = np.arctan2(-y if clockwise else y, x).astype(np.float64)
    angle *= 180.0 / np.pi
    angle += x_axis_azimuth_deg
    angle[(x == 0) & (y == 0)] = np.nan
    azimuth: NDArray[np.float64] = angle % 360.0
    return azimuth


def measured_x_axis_deg(layout: CloudLayout, data: bytes | memoryview) -> float | None:
    """The packet azimuth of the cloud frame's +X, measured: the circular median of the
    `azimuth` field less the clockwise angle from +X (`atan2(-y, x)`), to 0.01 deg; 0
    where there is no azimuth field (the azimuth is then that angle by definition); None
    where neither tells (no x and y, or no point with both)."""
    if "x" not in layout.fields or "y" not in layout.fields:
        return None
    if "azimuth" not in layout.fields:
        return 0.0
    with_field = point_azimuth_deg(layout, data, 0.0, stride=7)
    fields = {k: v for k, v in layout.fields.items() if k != "azimuth"}
    bare = CloudLayout(**{**{n: getattr(layout, n) for n in layout.__slots__}, "fields": fields})
    from_xy = point_azimuth_deg(bare, data, 0.0, stride=7)
    diff = (with_field - from_xy).reshape(-1)
    diff = diff[np.isfinite(diff)] % 360.0
    if not diff.size:
        return None
    centre = float(np.median((diff - diff[0] + 180.0) % 360.0 - 180.0)) + float(diff[0])
    return round(centre % 360.0, 2) % 360.0
