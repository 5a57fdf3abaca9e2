"""The layout of one serialized `sensor_msgs/PointCloud2`: header, fields, where the points are.

Read from the message bytes (ROS 1 or CDR, `logs.wire`), without a generic deserialiser and
without copying the point data: `CloudLayout.data_offset` is where the `height * row_step`
bytes of points start in the message, so the fields a reader needs are numpy views on it.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from syncaudit.errors import DecodeError
from syncaudit.logs import RawMessage
from syncaudit.logs.wire import cdr_align, cdr_byte_order, cdr_header, cdr_string, ros1_header

__all__ = ["DATATYPES", "CloudField", "CloudLayout", "cloud_layout"]

DATATYPES: dict[int, str] = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}
"""sensor_msgs/PointField datatype -> numpy kind and size (INT8 ... FLOAT64)."""
UINT64 = 9
"""Not in sensor_msgs/PointField; some drivers write it for uint64 nanosecond stamps."""


@dataclass(frozen=True, slots=True)
class CloudField:
    """One PointField: its byte offset in a point, datatype code and count."""

    name: str
    offset: int
    datatype: int
    count: int


@dataclass(frozen=True, slots=True)
class CloudLayout:
    """What a cloud's points look like and where they are in the message."""

    stamp_ns: int
    frame_id: str
    height: int
    width: int
    fields: dict[str, CloudField]
    is_bigendian: bool
    point_step: int
    row_step: int
    data_offset: int
    data_size: int

    @property
    def n_points(self) -> int:
        """Points in the cloud, valid or not (height * width)."""
        return self.height * self.width


def cloud_layout(msg: RawMessage) -> CloudLayout:
    """The layout of a PointCloud2 message; DecodeError (one line) where it is damaged."""
    data = msg.data
    try:
        if msg.encoding == "ros1":
            return _parse(data, "<", *_ros1_start(data), ros1=True)
        if msg.encoding == "cdr":
            order = cdr_byte_order(data)
            sec, nsec, frame, pos = cdr_header(data, 4, order)
            return _parse(data, order, sec, nsec, frame, pos, ros1=False)
    except struct.error:
        raise DecodeError(f"{msg.topic}: PointCloud2 message cut short") from None
    raise DecodeError(f"{msg.topic}: message encoding {msg.encoding!r} is not ROS (cdr/ros1)")


def _ros1_start(data: bytes | memoryview) -> tuple[int, int, str, int]:
    _, sec, nsec, frame, pos = ros1_header(data, 0)
    return sec, nsec, frame, pos


def _parse(
    data: bytes | memoryview, order: str, sec: int, nsec: int, frame: str, pos: int, *, ros1: bool
) -> CloudLayout:
    """Everything after the header, in either wire format."""

    def align(p: int, size: int) -> int:
        return p if ros1 else cdr_align(p, size)

    u32 = struct.Struct(order + "I")
    pos = align(pos, 4)
    height, width, n_fields = struct.unpack_from(order + "III", data, pos)
    pos += 12
    fields: dict[str, CloudField] = {}
    for _ in range(n_fields):
        name, pos = _string(data, pos, order, ros1)
        pos = align(pos, 4)
        (offset,) = u32.unpack_from(data, pos)
        datatype = data[pos + 4]
        pos = align(pos + 5, 4)
        (count,) = u32.unpack_from(data, pos)
        pos += 4
        fields[name] = CloudField(name, int(offset), int(datatype), int(count))
    is_bigendian = bool(data[pos])
    pos = align(pos + 1, 4)
    point_step, row_step, size = struct.unpack_from(order + "III", data, pos)
    pos += 12
    if pos + size > len(data):
        raise DecodeError(f"PointCloud2 data of {size} bytes is cut short")
    if point_step <= 0 and height * width:
        raise DecodeError("PointCloud2 point_step is 0")
    if height * row_step > size or row_step < width * point_step:
        raise DecodeError(
            f"PointCloud2 of {height}x{width} points, point_step {point_step}, row_step "
            f"{row_step}: {size} data bytes do not hold it"
        )
    return CloudLayout(
        stamp_ns=sec * 1_000_000_000 + nsec,
        frame_id=frame,
        height=int(height),
        width=int(width),
        fields=fields,
        is_bigendian=is_bigendian,
        point_step=int(point_step),
        row_step=int(row_step),
        data_offset=pos,
        data_size=int(size),
    )


def _string(data: bytes | memoryview, pos: int, order: str, ros1: bool) -> tuple[str, int]:
    if ros1:
        (length,) = struct.unpack_from("<I", data, pos)
        return str(bytes(data[pos + 4 : pos + 4 + length]), "utf-8", "replace"), pos + 4 + length
    return cdr_string(data, pos, order)
