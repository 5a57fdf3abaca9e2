"""Struct readers for the small per-frame messages whose layout syncaudit knows, and for
/tf_static's TFMessage (`read_tf_message`).

rosbags deserialises any message but costs ~30 us each; these fixed-layout CDR messages
(ROS 2) arrive once per camera frame, so the audit reads their fields with `struct` in
a few microseconds, in CDR (ROS 2) and ROS 1 serialization alike. Anything else goes
through rosbags. Tests check the two give identical rows.

Headers, strings and the encapsulation are read by `syncaudit.logs.wire`. Damaged bytes (a
message cut short, a length past its end, an encapsulation other than CDR_LE/CDR_BE) never
raise: `read_fast` returns a namespace whose `damaged` attribute says what is
wrong, so the row functions can skip the message with a counted warning (a damaged
camera message should not stop the audit of everything else). Strings decode leniently
(bit flips become U+FFFD): the audit uses their text only to tell cameras sharing a topic
apart (`camera`, `header.frame_id`), where a damaged name matches no camera of the rig.
"""

from __future__ import annotations

import struct
from types import SimpleNamespace
from typing import Any

from syncaudit.logs.wire import (
    WireError,
    cdr_align,
    cdr_byte_order,
    cdr_header,
    cdr_string,
    ros1_header,
    ros1_string,
)

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
    """Reads CDR primitives in order, aligned relative to after the 4-byte header.

    With `ros1`, reads ROS 1 serialization instead: little-endian, packed (no alignment),
    strings without terminator, and the std_msgs/Header `seq` before the stamp.
    """

    __slots__ = ("data", "fmt", "order", "pos", "ros1")

    def __init__(self, data: bytes | memoryview, *, ros1: bool = False) -> None:
        self.data = data
        self.ros1 = ros1
        self.order = "<" if ros1 else cdr_byte_order(data)
        self.fmt = _LE if self.order == "<" else _BE
        self.pos = 0 if ros1 else 4

    def _get(self, code: str, size: int) -> Any:
        rem = 0 if self.ros1 else (self.pos - 4) % size
        if rem:
            self.pos += size - rem
        if self.pos + size > len(self.data):
            raise WireError(f"a {size}-byte field at byte {self.pos} is missing or cut", cut=True)
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
        if self.ros1:
            text, self.pos = ros1_string(self.data, self.pos)
        else:
            text, self.pos = cdr_string(self.data, self.pos, self.order)
        return text

    def time(self) -> SimpleNamespace:
        return SimpleNamespace(sec=self.u32() if self.ros1 else self.i32(), nanosec=self.u32())

    def header(self) -> SimpleNamespace:
        if self.ros1:
            seq, sec, nsec, frame_id, self.pos = ros1_header(self.data, self.pos)
            return _r1_header_fields(seq, sec, nsec, frame_id)
        sec, nsec, frame_id, self.pos = cdr_header(self.data, self.pos, self.order)
        return _cdr_header_fields(sec, nsec, frame_id)


def _r1_header_fields(seq: int, sec: int, nsec: int, frame_id: str) -> SimpleNamespace:
    """A ROS 1 std_msgs/Header's fields."""
    return SimpleNamespace(seq=seq, stamp=SimpleNamespace(sec=sec, nanosec=nsec), frame_id=frame_id)


def _cdr_header_fields(sec: int, nsec: int, frame_id: str) -> SimpleNamespace:
    """A ROS 2 std_msgs/Header's fields."""
    return SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=nsec), frame_id=frame_id)


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


# ROS 1 serialization is packed little-endian: each message is read with one unpack per
# run of fixed fields between its strings. Bytes that do not fit (a struct.error, a
# WireError) fall back to `_Cursor`, which says what is damaged.
_R1_EXPOSURE = struct.Struct("<IIId")  # frame_sequence, exposure_start, exposure_duration
_R1_TRIGGER = struct.Struct("<I10Id")  # frame_sequence, five times, applied_delay
_R1_META = struct.Struct("<QhI")  # camera_time, brightness, exposure_time


def _exposure_fields(
    header: SimpleNamespace, camera: str, sequence: int, sec: int, nsec: int, duration: float
) -> SimpleNamespace:
    """A CameraExposure's fields, as either serialization's one-pass reader found them."""
    return SimpleNamespace(
        header=header,
        camera=camera,
        frame_sequence=sequence,
        exposure_start=SimpleNamespace(sec=sec, nanosec=nsec),
        exposure_duration=duration,
    )


def _trigger_fields(
    header: SimpleNamespace, camera: str, sequence: int, t: list[int], delay: float
) -> SimpleNamespace:
    """A TriggerEvent's fields; `t` the five times' (sec, nanosec) in field order."""
    return SimpleNamespace(
        header=header,
        camera=camera,
        frame_sequence=sequence,
        lidar_packet_time=SimpleNamespace(sec=t[0], nanosec=t[1]),
        lidar_driver_time=SimpleNamespace(sec=t[2], nanosec=t[3]),
        camera_driver_time=SimpleNamespace(sec=t[4], nanosec=t[5]),
        camera_sensor_time=SimpleNamespace(sec=t[6], nanosec=t[7]),
        exposure_start_time=SimpleNamespace(sec=t[8], nanosec=t[9]),
        applied_delay=delay,
    )


def _meta_fields(
    header: SimpleNamespace, camera_time: int, brightness: int, exposure_time: int
) -> SimpleNamespace:
    """An ImageMetaData's fields."""
    return SimpleNamespace(
        header=header, camera_time=camera_time, brightness=brightness, exposure_time=exposure_time
    )


def _r1_camera_exposure(data: bytes | memoryview) -> SimpleNamespace:
    seq, sec, nsec, frame_id, pos = ros1_header(data, 0)
    header = _r1_header_fields(seq, sec, nsec, frame_id)
    camera, pos = ros1_string(data, pos)
    return _exposure_fields(header, camera, *_R1_EXPOSURE.unpack_from(data, pos))


def _r1_trigger_event(data: bytes | memoryview) -> SimpleNamespace:
    seq, sec, nsec, frame_id, pos = ros1_header(data, 0)
    header = _r1_header_fields(seq, sec, nsec, frame_id)
    camera, pos = ros1_string(data, pos)
    sequence, *t, delay = _R1_TRIGGER.unpack_from(data, pos)
    return _trigger_fields(header, camera, sequence, t, delay)


def _r1_image_meta(data: bytes | memoryview) -> SimpleNamespace:
    seq, sec, nsec, frame_id, pos = ros1_header(data, 0)
    header = _r1_header_fields(seq, sec, nsec, frame_id)
    return _meta_fields(header, *_R1_META.unpack_from(data, pos))


# CDR (ROS 2) likewise, one unpack per run of fixed fields, in either byte order; CDR
# aligns each primitive to its size counted from after the 4-byte encapsulation header,
# so a run after a string starts at the next multiple of 4 and an f64 or u64 at the next
# multiple of 8 (relative). A message that does not fit falls back to `_Cursor`.
_CDR_FORMATS = {
    order: (
        struct.Struct(order + "IiI"),  # frame_sequence, exposure_start
        struct.Struct(order + "I" + "iI" * 5),  # frame_sequence, five times
        struct.Struct(order + "d"),
        struct.Struct(order + "Qh2xI"),  # camera_time, brightness, exposure_time
    )
    for order in "<>"
}


def _cdr_camera_exposure(data: bytes | memoryview, order: str) -> SimpleNamespace:
    run, _trigger_run, f64, _meta_run = _CDR_FORMATS[order]
    sec, nsec, frame_id, pos = cdr_header(data, 4, order)
    camera, pos = cdr_string(data, pos, order)
    pos = cdr_align(pos, 4)
    sequence, start_sec, start_nsec = run.unpack_from(data, pos)
    (duration,) = f64.unpack_from(data, cdr_align(pos + run.size, 8))
    header = _cdr_header_fields(sec, nsec, frame_id)
    return _exposure_fields(header, camera, sequence, start_sec, start_nsec, duration)


def _cdr_trigger_event(data: bytes | memoryview, order: str) -> SimpleNamespace:
    _exposure_run, run, f64, _meta_run = _CDR_FORMATS[order]
    sec, nsec, frame_id, pos = cdr_header(data, 4, order)
    camera, pos = cdr_string(data, pos, order)
    pos = cdr_align(pos, 4)
    sequence, *t = run.unpack_from(data, pos)
    (delay,) = f64.unpack_from(data, cdr_align(pos + run.size, 8))
    return _trigger_fields(_cdr_header_fields(sec, nsec, frame_id), camera, sequence, t, delay)


def _cdr_image_meta(data: bytes | memoryview, order: str) -> SimpleNamespace:
    sec, nsec, frame_id, pos = cdr_header(data, 4, order)
    fields = _CDR_FORMATS[order][3].unpack_from(data, cdr_align(pos, 8))
    return _meta_fields(_cdr_header_fields(sec, nsec, frame_id), *fields)


CDR_READERS = {
    "syncaudit_msgs/msg/CameraExposure": _cdr_camera_exposure,
    "syncaudit_msgs/msg/TriggerEvent": _cdr_trigger_event,
    "flir_camera_msgs/msg/ImageMetaData": _cdr_image_meta,
}
"""The FAST_READERS' types read from CDR bytes in one pass (the same fields)."""


ROS1_READERS = {
    "syncaudit_msgs/msg/CameraExposure": _r1_camera_exposure,
    "syncaudit_msgs/msg/TriggerEvent": _r1_trigger_event,
    "flir_camera_msgs/msg/ImageMetaData": _r1_image_meta,
}
"""The FAST_READERS' types read from ROS 1 bytes in one pass (the same fields)."""


FAST_READERS = {
    "syncaudit_msgs/msg/CameraExposure": _camera_exposure,
    "syncaudit_msgs/msg/TriggerEvent": _trigger_event,
    "flir_camera_msgs/msg/ImageMetaData": _image_meta,
}


def has_fast_reader(msgtype: str, encoding: str) -> bool:
    """True where `read_fast` reads this type and encoding (else rosbags must)."""
    return encoding in ("cdr", "ros1") and msgtype in FAST_READERS


def read_fast(data: bytes | memoryview, msgtype: str, encoding: str) -> SimpleNamespace | None:
    """The fields the audit needs, or None where this type/encoding has no fast reader.

    Where the bytes do not fit the layout, the namespace holds only `damaged`: what is
    wrong, e.g. "truncated CameraExposure (7 bytes): a 4-byte field at byte 8 is missing".
    """
    if not has_fast_reader(msgtype, encoding):
        return None
    name = msgtype.rsplit("/", 1)[-1]
    ros1 = encoding == "ros1"
    order = "<"
    if not ros1:
        try:
            order = cdr_byte_order(data)
        except WireError:
            head = bytes(data[0:4]).hex() or "nothing"
            return SimpleNamespace(
                damaged=f"{name} of {len(data)} bytes has no CDR encapsulation header ({head})"
            )
    try:
        return ROS1_READERS[msgtype](data) if ros1 else CDR_READERS[msgtype](data, order)
    except (struct.error, WireError):
        pass  # damaged: the cursor below says where
    try:
        return FAST_READERS[msgtype](_Cursor(data, ros1=ros1))
    except WireError as exc:
        return SimpleNamespace(damaged=_damage(name, len(data), exc))


def _damage(name: str, size: int, exc: WireError) -> str:
    """What is wrong with a message of `size` bytes, as `read_fast` says it."""
    return f"{'truncated' if exc.cut else 'damaged'} {name} ({size} bytes): {exc}"


# tf2_msgs/TFMessage, for the camera mounts in /tf_static: a guessed rig then needs no type
# registry built from the log's schemas (deserialising one TFMessage through rosbags costs
# ~0.1 s: the registry and rosbags' code generator). Bytes that do not fit give None, and
# the caller asks rosbags, which says what is wrong.
_CDR_TRANSFORM = {order: struct.Struct(order + "7d") for order in "<>"}
_CDR_COUNT = {order: struct.Struct(order + "I") for order in "<>"}  # the transforms' count
_R1_COUNT = struct.Struct("<I")
_R1_TRANSFORM = struct.Struct("<7d")  # translation x, y, z; rotation x, y, z, w
_MIN_CDR_TRANSFORM = 8 + 4 + 1 + 3 + 4 + 1 + 3 + 56
"""Fewest bytes one TransformStamped takes in CDR (empty strings, padding): a count
claiming more than fit in the message is refused before any loop."""
_MIN_R1_TRANSFORM = 16 + 4 + 56


def read_tf_message(data: bytes | memoryview, encoding: str) -> SimpleNamespace | None:
    """A TFMessage's `transforms`, each with `header`, `child_frame_id` and
    `transform.translation` / `transform.rotation` (x, y, z, w); None where the bytes do
    not fit (or the encoding is not cdr/ros1)."""
    try:
        if encoding == "ros1":
            return _r1_tf_message(data)
        if encoding == "cdr":
            return _cdr_tf_message(data, cdr_byte_order(data))
    except (struct.error, WireError):
        return None
    return None


def _transform(header: SimpleNamespace, child: str, values: tuple[float, ...]) -> SimpleNamespace:
    tx, ty, tz, qx, qy, qz, qw = values
    return SimpleNamespace(
        header=header,
        child_frame_id=child,
        transform=SimpleNamespace(
            translation=SimpleNamespace(x=tx, y=ty, z=tz),
            rotation=SimpleNamespace(x=qx, y=qy, z=qz, w=qw),
        ),
    )


def _cdr_tf_message(data: bytes | memoryview, order: str) -> SimpleNamespace:
    values = _CDR_TRANSFORM[order]
    (count,) = _CDR_COUNT[order].unpack_from(data, 4)
    if count * _MIN_CDR_TRANSFORM > len(data):
        raise WireError(f"{count} transforms cannot fit {len(data)} bytes", cut=True)
    pos, transforms = 8, []
    for _ in range(count):
        sec, nsec, frame_id, pos = cdr_header(data, pos, order)
        child, pos = cdr_string(data, pos, order)
        pos = cdr_align(pos, 8)
        header = _cdr_header_fields(sec, nsec, frame_id)
        transforms.append(_transform(header, child, values.unpack_from(data, pos)))
        pos += values.size
    return SimpleNamespace(transforms=transforms)


def _r1_tf_message(data: bytes | memoryview) -> SimpleNamespace:
    (count,) = _R1_COUNT.unpack_from(data, 0)
    if count * _MIN_R1_TRANSFORM > len(data):
        raise WireError(f"{count} transforms cannot fit {len(data)} bytes", cut=True)
    pos, transforms = 4, []
    for _ in range(count):
        seq, sec, nsec, frame_id, pos = ros1_header(data, pos)
        child, pos = ros1_string(data, pos)
        header = _r1_header_fields(seq, sec, nsec, frame_id)
        transforms.append(_transform(header, child, _R1_TRANSFORM.unpack_from(data, pos)))
        pos += _R1_TRANSFORM.size
    return SimpleNamespace(transforms=transforms)
