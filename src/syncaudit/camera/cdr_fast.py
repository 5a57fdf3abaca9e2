"""Struct readers for the small per-frame messages whose layout syncaudit knows.

rosbags deserialises any message but costs ~30 us each; these fixed-layout CDR messages
(ROS 2) arrive once per camera frame, so the audit reads their fields with `struct` in
a few microseconds. Anything else, or ROS 1 bytes, goes through rosbags. Tests check
the two give identical rows.
"""

from __future__ import annotations

import struct
from types import SimpleNamespace
from typing import Any

_LE = {
    "I": struct.Struct("<I"),
    "i": struct.Struct("<i"),
    "d": struct.Struct("<d"),
    "Q": struct.Struct("<Q"),
    "h": struct.Struct("<h"),
    "f": struct.Struct("<f"),
}
_BE = {k: struct.Struct(">" + v.format[1:]) for k, v in _LE.items()}


class _Cursor:
    """Reads CDR primitives in order, aligned relative to after the 4-byte header."""

    __slots__ = ("data", "fmt", "pos")

    def __init__(self, data: bytes | memoryview) -> None:
        self.data = data
        self.fmt = _LE if bytes(data[1:2]) in (b"\x01", b"\x03") else _BE
        self.pos = 4

    def _get(self, code: str, size: int) -> Any:
        rem = (self.pos - 4) % size
        if rem:
            self.pos += size - rem
        (value,) = self.fmt[code].unpack_from(self.data, self.pos)
        self.pos += size
        return value

    def u32(self) -> int:
        return int(self._get("I", 4))

    def i32(self) -> int:
        return int(self._get("i", 4))

    def f64(self) -> float:
        return float(self._get("d", 8))

    def f32(self) -> float:
        return float(self._get("f", 4))

    def u64(self) -> int:
        return int(self._get("Q", 8))

    def i16(self) -> int:
        return int(self._get("h", 2))

    def string(self) -> str:
        length = self.u32()
        text = bytes(self.data[self.pos : self.pos + length - 1]).decode()
        self.pos += length
        return text

    def time(self) -> SimpleNamespace:
        return SimpleNamespace(sec=self.i32(), nanosec=self.u32())

    def header(self) -> SimpleNamespace:
        return SimpleNamespace(stamp=self.time(), frame_id=self.string())


def _camera_exposure(c: _Cursor) -> SimpleNamespace:
    return SimpleNamespace(
        header=c.header(),
        camera=c.string(),
        frame_sequence=c.u32(),
        exposure_start=c.time(),
        exposure_duration=c.f64(),
    )


def _trigger_event(c: _Cursor) -> SimpleNamespace:
    return SimpleNamespace(
        header=c.header(),
        camera=c.string(),
        frame_sequence=c.u32(),
        lidar_packet_time=c.time(),
        lidar_driver_time=c.time(),
        camera_driver_time=c.time(),
        camera_sensor_time=c.time(),
        exposure_start_time=c.time(),
        applied_delay=c.f64(),
    )


def _image_meta(c: _Cursor) -> SimpleNamespace:
    header = c.header()
    return SimpleNamespace(
        header=header, camera_time=c.u64(), brightness=c.i16(), exposure_time=c.u32()
    )


FAST_READERS = {
    "syncaudit_msgs/msg/CameraExposure": _camera_exposure,
    "syncaudit_msgs/msg/TriggerEvent": _trigger_event,
    "flir_camera_msgs/msg/ImageMetaData": _image_meta,
}


def has_fast_reader(msgtype: str, encoding: str) -> bool:
    """True where `read_fast` reads this type and encoding (else rosbags must)."""
    return encoding == "cdr" and msgtype in FAST_READERS


def read_fast(data: bytes | memoryview, msgtype: str, encoding: str) -> SimpleNamespace | None:
    """The fields the audit needs, or None where this type/encoding has no fast reader."""
    if not has_fast_reader(msgtype, encoding):
        return None
    return FAST_READERS[msgtype](_Cursor(data))
