"""tf2_msgs/TFMessage read with `struct`, in CDR (either byte order) and ROS 1 serialization.

What the camera mounts in /tf_static need (each transform's frames and rotation), without
rosbags: deserialising one TFMessage through rosbags first builds the log's type registry
and imports its code generator (~0.1 s, the larger part of a guessed rig's start-up).
Bytes that do not fit the layout give None: the caller then asks rosbags, which says what
is wrong. Strings decode leniently, as `cdr_fast` does.
"""

from __future__ import annotations

import struct
from types import SimpleNamespace

_CDR_LE_IDS = (b"\x00\x01", b"\x00\x03")
_CDR_IDS = (b"\x00\x00", b"\x00\x02", *_CDR_LE_IDS)
_FORMATS = {
    order: (struct.Struct(order + "I"), struct.Struct(order + "iI"), struct.Struct(order + "7d"))
    for order in "<>"
}
_ROS1_HEAD = struct.Struct("<IIII")  # seq, stamp sec, stamp nsec, frame_id length
_ROS1_U32 = struct.Struct("<I")
_ROS1_DOUBLES = struct.Struct("<7d")
_MIN_CDR_TRANSFORM = 8 + 4 + 1 + 3 + 4 + 1 + 3 + 56
"""Fewest bytes one TransformStamped takes in CDR (empty strings, padding): a count
claiming more than fit in the message is refused before any loop."""
_MIN_ROS1_TRANSFORM = 16 + 4 + 56


class _UnfitError(Exception):
    """The bytes do not fit a TFMessage (internal)."""


def read_tf_message(data: bytes | memoryview, encoding: str) -> SimpleNamespace | None:
    """`transforms`, each with `header.frame_id`, `child_frame_id` and
    `transform.translation` / `transform.rotation` (x, y, z, w); None where the bytes do
    not fit (or the encoding is not cdr/ros1)."""
    try:
        if encoding == "ros1":
            return _ros1(data)
        if encoding == "cdr" and len(data) >= 8 and bytes(data[0:2]) in _CDR_IDS:
            return _cdr(data, "<" if bytes(data[0:2]) in _CDR_LE_IDS else ">")
    except (_UnfitError, struct.error, UnicodeDecodeError):
        return None
    return None


def _transform(frame: str, child: str, values: tuple[float, ...]) -> SimpleNamespace:
    tx, ty, tz, qx, qy, qz, qw = values
    return SimpleNamespace(
        header=SimpleNamespace(frame_id=frame),
        child_frame_id=child,
        transform=SimpleNamespace(
            translation=SimpleNamespace(x=tx, y=ty, z=tz),
            rotation=SimpleNamespace(x=qx, y=qy, z=qz, w=qw),
        ),
    )


def _cdr(data: bytes | memoryview, order: str) -> SimpleNamespace:
    u32, stamp, doubles = _FORMATS[order]
    (count,) = u32.unpack_from(data, 4)
    if count * _MIN_CDR_TRANSFORM > len(data):
        raise _UnfitError
    pos, transforms = 8, []
    for _ in range(count):
        pos = _align(pos, 4) + stamp.size
        frame, pos = _cdr_string(data, pos, u32)
        child, pos = _cdr_string(data, _align(pos, 4), u32)
        pos = _align(pos, 8)
        transforms.append(_transform(frame, child, doubles.unpack_from(data, pos)))
        pos += doubles.size
    return SimpleNamespace(transforms=transforms)


def _align(pos: int, size: int) -> int:
    """`pos` moved to the next multiple of `size` counted from byte 4 (after the header)."""
    return pos + (-(pos - 4) % size)


def _cdr_string(data: bytes | memoryview, pos: int, u32: struct.Struct) -> tuple[str, int]:
    (length,) = u32.unpack_from(data, pos)
    end = pos + 4 + length
    if length < 1 or end > len(data):
        raise _UnfitError
    return bytes(data[pos + 4 : end - 1]).decode(errors="replace"), end


def _ros1(data: bytes | memoryview) -> SimpleNamespace:
    (count,) = _ROS1_U32.unpack_from(data, 0)
    if count * _MIN_ROS1_TRANSFORM > len(data):
        raise _UnfitError
    pos, transforms = 4, []
    for _ in range(count):
        _seq, _sec, _nsec, length = _ROS1_HEAD.unpack_from(data, pos)
        frame, pos = _ros1_text(data, pos + _ROS1_HEAD.size, length)
        (length,) = _ROS1_U32.unpack_from(data, pos)
        child, pos = _ros1_text(data, pos + 4, length)
        transforms.append(_transform(frame, child, _ROS1_DOUBLES.unpack_from(data, pos)))
        pos += _ROS1_DOUBLES.size
    return SimpleNamespace(transforms=transforms)


def _ros1_text(data: bytes | memoryview, start: int, length: int) -> tuple[str, int]:
    end = start + length
    if end > len(data):
        raise _UnfitError
    return bytes(data[start:end]).decode(errors="replace"), end
