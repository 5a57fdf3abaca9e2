"""Camera frames and triggers as tables (see syncaudit.columns.camera), one message at a time.

Image headers are read straight from the serialized bytes (the stamp sits at a fixed
offset in both encodings), so large image payloads are never deserialised. Exposure and
trigger messages are small and go through rosbags with the log's own definitions.
The row functions are pure (message in, tuple out) so worker processes can run them.

A damaged camera message (cut short, empty, a stamp or duration no sensor writes) becomes
a `DamagedRow` naming topic, log time and what is wrong, never an exception: the builder
skips it and the audit warns "camera front: 3 damaged messages skipped on
/cameras/front/exposure (...)". The audit of the rest goes on; only a topic whose every
message is damaged stops it (LogReadError, exit 3), since nothing of it can be judged.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from syncaudit.camera.rowstore import DamagedRow, Row, RowStore
from syncaudit.camera.sequences import SequenceCounter, field_counter, header_seq_counter
from syncaudit.columns.camera import CAMERA_EXPOSURE, FRAME_COLUMNS, TRIGGER_COLUMNS, CameraTables
from syncaudit.errors import LogReadError
from syncaudit.logs import RawMessage
from syncaudit.logs.wire import (
    WireError,
    cdr_byte_order,
    cdr_string,
    cdr_time,
    ros1_string,
    ros1_time,
)
from syncaudit.rig import CameraConfig

if TYPE_CHECKING:
    from syncaudit.columns.table import Table

_ROS1_SEQ = struct.Struct("<I")

_HEADER_BYTES = 12
"""Bytes up to the end of the header stamp: ROS 1 seq + stamp, or CDR encapsulation + stamp."""
MAX_DURATION_S = 3600.0
"""Exposures or delays longer than this (or not finite) are damaged values, not timing."""

ImageRow = tuple[int, int, int | None, str]
"""(header stamp ns, log time ns, ROS 1 seq or None, header frame_id)."""

CAMERA_FIELD_TYPES = frozenset(
    {"syncaudit_msgs/msg/TriggerEvent", "syncaudit_msgs/msg/CameraExposure"}
)
"""Types whose `camera` field names the rig camera a message belongs to."""


def header_stamp_ns(msg: RawMessage) -> int:
    """std_msgs/Header stamp of a message whose first field is the header.

    Raises LogReadError (naming topic and log time) where the message is too short to
    hold one, its CDR encapsulation is not CDR_LE/CDR_BE or its stamp is out of range.
    """
    return _header_stamp(msg)[0]


def _header_stamp(msg: RawMessage) -> tuple[int, str]:
    """header_stamp_ns and the byte order of the message's fields ("<" or ">")."""
    data = msg.data
    if len(data) < _HEADER_BYTES:
        raise LogReadError(_where(msg, f"{len(data)} bytes cannot hold a header stamp"))
    try:
        if msg.encoding == "ros1":
            order = "<"
            sec, nsec, _end = ros1_time(data, 4)
        else:
            order = cdr_byte_order(data)
            sec, nsec, _end = cdr_time(data, 4, order)
    except WireError as exc:
        raise LogReadError(_where(msg, str(exc))) from None
    if sec < 0 or nsec >= 1_000_000_000:
        raise LogReadError(_where(msg, f"header stamp {sec} s {nsec} ns out of range"))
    return int(sec) * 1_000_000_000 + int(nsec), order


def header_frame_id(msg: RawMessage) -> str:
    """`header.frame_id` of a message whose first field is a std_msgs/Header, from its bytes.

    "" where the bytes hold none (image_row reports a message too short for its stamp).
    """
    try:
        return _raw_frame_id(msg, "<" if msg.encoding == "ros1" else cdr_byte_order(msg.data))
    except WireError:
        return ""


def _raw_frame_id(msg: RawMessage, order: str) -> str:
    """`header.frame_id` of a message of that byte order; WireError where it holds none."""
    if msg.encoding == "ros1":
        return ros1_string(msg.data, _HEADER_BYTES)[0]
    return cdr_string(msg.data, _HEADER_BYTES, order)[0]


def _where(msg: RawMessage, what: str) -> str:
    return f"{msg.topic} at log time {msg.log_time_ns / 1e9:.9f} s: {what}"


def _damaged(msg: RawMessage, reason: str) -> DamagedRow:
    return DamagedRow(msg.topic, msg.log_time_ns, reason)


def _duration_ns(seconds: Any, what: str) -> int:
    """Seconds as int64 ns; ValueError for values no camera reports (NaN, inf, hours)."""
    value = float(seconds)
    if not math.isfinite(value) or abs(value) > MAX_DURATION_S:
        raise ValueError(f"{what} {value!r} s is not a duration")
    return round(value * 1e9)


def _time_ns(t: Any) -> int:
    sec, nanosec = int(t.sec), int(t.nanosec)
    if sec < 0 or not 0 <= nanosec < 1_000_000_000:
        raise ValueError(f"time {sec} s {nanosec} ns out of range")
    return sec * 1_000_000_000 + nanosec


def _ros1_seq(msg: RawMessage) -> int | None:
    if msg.encoding == "ros1" and len(msg.data) < _ROS1_SEQ.size:
        raise LogReadError(_where(msg, f"{len(msg.data)} bytes cannot hold a header seq"))
    return int(_ROS1_SEQ.unpack_from(msg.data, 0)[0]) if msg.encoding == "ros1" else None


def exposure_start_ns(stamp: int, duration: int | None, semantics: str) -> int:
    """Exposure start from a header stamp and what the stamp marks."""
    if duration is None or semantics in ("exposure_start", "trigger"):
        return stamp
    return stamp - (duration // 2 if semantics == "exposure_middle" else duration)


def image_row(msg: RawMessage) -> ImageRow | DamagedRow:
    """The header of an image (or CameraInfo / WFOVImage) message; DamagedRow if unreadable."""
    try:
        stamp_ns, order = _header_stamp(msg)
        seq = _ros1_seq(msg)
    except LogReadError as exc:
        return _damaged(msg, str(exc).rsplit(": ", 1)[-1])
    try:
        frame_id = _raw_frame_id(msg, order)
    except WireError:
        frame_id = ""
    return stamp_ns, msg.log_time_ns, seq, frame_id


def _named_camera(msg: RawMessage, m: Any, camera: str) -> str:
    """The camera a record names in its `camera` field (syncaudit types), else `camera`."""
    if msg.msgtype in CAMERA_FIELD_TYPES:
        named = str(getattr(m, "camera", ""))
        if named:
            return named
    return camera


def _frame_id(m: Any) -> str:
    """`header.frame_id` of a deserialised message ("" where it has no header)."""
    header = getattr(m, "header", None)
    return str(getattr(header, "frame_id", "")) if header is not None else ""


def exposure_row(
    msg: RawMessage, m: Any, camera: str, semantics: str
) -> tuple[Any, ...] | DamagedRow:
    """A FRAME_COLUMNS row from one deserialised exposure message; DamagedRow if unreadable.

    Its `camera` is the one the message names (CameraExposure.camera), else `camera`; its
    exposure start follows `semantics` where the message states none (the builder derives
    it again with its own camera's `stamp`: a shared topic's cameras may differ).
    """
    damage = getattr(m, "damaged", None)
    if damage is not None:
        return _damaged(msg, str(damage))
    try:
        return _exposure_row(msg, m, camera, semantics)
    except (ValueError, LogReadError) as exc:
        return _damaged(msg, str(exc).rsplit(": ", 1)[-1])


def _exposure_row(msg: RawMessage, m: Any, camera: str, semantics: str) -> tuple[Any, ...]:
    stamp = _time_ns(m.header.stamp)
    seq = _ros1_seq(msg)
    duration: int | None
    if msg.msgtype == "syncaudit_msgs/msg/CameraExposure":
        start = _time_ns(m.exposure_start)
        duration = _duration_ns(m.exposure_duration, "exposure_duration")
        seq = int(m.frame_sequence)
    elif msg.msgtype == "flir_camera_msgs/msg/ImageMetaData":
        duration = int(m.exposure_time) * 1000
        start = exposure_start_ns(stamp, duration, semantics)
    else:  # wfov_camera_msgs/msg/WFOVImage: shutter in seconds, negative = invalid
        shutter = float(m.shutter)
        duration = _duration_ns(shutter, "shutter") if shutter >= 0 else None
        start = exposure_start_ns(stamp, duration, semantics)
    return (
        _named_camera(msg, m, camera),
        seq,
        stamp,
        msg.log_time_ns,
        start,
        duration,
        msg.msgtype,
        _frame_id(m),
    )


def trigger_row(msg: RawMessage, m: Any, camera: str) -> tuple[Any, ...] | DamagedRow:
    """A TRIGGER_COLUMNS row from one deserialised trigger message; DamagedRow if unreadable.

    Its `camera` is the one the message names (TriggerEvent.camera), else `camera`.
    """
    damage = getattr(m, "damaged", None)
    if damage is not None:
        return _damaged(msg, str(damage))
    try:
        return _trigger_row(msg, m, camera)
    except (ValueError, LogReadError) as exc:
        return _damaged(msg, str(exc).rsplit(": ", 1)[-1])


def _trigger_row(msg: RawMessage, m: Any, camera: str) -> tuple[Any, ...]:
    if msg.msgtype == "syncaudit_msgs/msg/TriggerEvent":
        return (
            _named_camera(msg, m, camera),
            int(m.frame_sequence),
            msg.log_time_ns,
            _time_ns(m.lidar_packet_time),
            _time_ns(m.lidar_driver_time),
            _time_ns(m.camera_driver_time),
            _time_ns(m.camera_sensor_time),
            _time_ns(m.exposure_start_time),
            _duration_ns(m.applied_delay, "applied_delay"),
            msg.msgtype,
            _frame_id(m),
        )
    seq: int | None = None
    if msg.msgtype == "builtin_interfaces/msg/Time":
        # A bare time: nothing names the camera, and no header holds a seq (its first
        # four bytes are the seconds, in ROS 1 too).
        sent, frame_id = _time_ns(m), ""
    else:  # sensor_msgs/TimeReference: frame_id "not used" by the message's docs; source
        sent, frame_id = _time_ns(m.time_ref), _frame_id(m) or str(getattr(m, "source", ""))
        seq = _ros1_seq(msg)
    return (
        camera,
        seq,
        msg.log_time_ns,
        None,
        None,
        None,
        sent,
        None,
        None,
        msg.msgtype,
        frame_id,
    )


@dataclass(slots=True)
class CameraTableBuilder:
    """Collects one camera's rows as they stream by, then builds its tables."""

    camera: CameraConfig
    images: RowStore = field(default_factory=lambda: RowStore(_image_table))
    exposures: RowStore = field(default_factory=lambda: RowStore(_frame_table))
    triggers: RowStore = field(default_factory=lambda: RowStore(_trigger_table))
    shared_topic_notes: list[str] = field(default_factory=list)
    topic_readers: dict[str, tuple[str, tuple[str, ...]]] = field(default_factory=dict)
    """Kind ('image', 'exposure', 'trigger') -> (topic it reads, the cameras reading it)."""

    def sequence_counter(self, kind: str, source: str | None) -> SequenceCounter:
        """What the `frame_sequence` of its `kind` rows count, given their message type."""
        if source in CAMERA_FIELD_TYPES:  # the frame counter of the camera it names
            return field_counter(source, self.camera.name)
        topic, cameras = self.topic_readers.get(kind, (None, (self.camera.name,)))
        return header_seq_counter(topic, cameras)

    def build(self) -> CameraTables:
        """The camera's frame, image and trigger tables, damaged messages left out.

        Raises LogReadError where every message of one of its topics is damaged.
        """
        import numpy as np  # deferred: worker processes extract rows without numpy

        from syncaudit.columns.table import str_column

        cam = self.camera
        images, image_warning = _readable(cam.name, self.images)
        exposures, exposure_warning = _readable(cam.name, self.exposures)
        triggers, trigger_warning = _readable(cam.name, self.triggers)
        warnings = tuple(w for w in (image_warning, exposure_warning, trigger_warning) if w)
        exposure_source = str(exposures["source"][0]) if len(exposures) else None
        trigger_source = str(triggers["source"][0]) if len(triggers) else None
        if len(exposures):
            frames = _restamped(exposures, cam.stamp)
        else:
            frames = _frames_from_images(images, cam)
        # Rows from a shared topic carry what the message names; the table is this camera's.
        frames = frames.with_columns({"camera": str_column([cam.name] * len(frames))})
        frames = frames.take(np.argsort(frames["log_time_ns"], kind="stable"))
        triggers = triggers.with_columns({"camera": str_column([cam.name] * len(triggers))})
        return CameraTables(
            cam.name,
            images,
            frames,
            triggers,
            exposure_source,
            trigger_source,
            warnings,
            tuple(self.shared_topic_notes),
            self.sequence_counter("exposure" if len(exposures) else "image", exposure_source),
            self.sequence_counter("trigger", trigger_source),
        )


def _frames_from_images(images: Table, cam: CameraConfig) -> Table:
    """One frame per image where the log has no exposure records (the rig's assumed
    exposure, if it states one, gives each its start and duration)."""
    from syncaudit.columns.table import Table, int_column, str_column

    assumed = None if cam.assumed_exposure_us is None else round(cam.assumed_exposure_us * 1e3)
    stamps = images["header_stamp_ns"].tolist()
    n = len(stamps)
    return Table(
        {
            "camera": str_column([cam.name] * n),
            "frame_sequence": images["frame_sequence"],
            "header_stamp_ns": images["header_stamp_ns"],
            "log_time_ns": images["log_time_ns"],
            "exposure_start_ns": int_column(
                exposure_start_ns(s, assumed, cam.stamp) if assumed else None for s in stamps
            ),
            "exposure_duration_ns": int_column([assumed] * n),
            "source": str_column(["image" if assumed is None else "image+assumed_exposure"] * n),
            "frame_id": images["frame_id"],
        },
        n,
    )


def _restamped(frames: Table, semantics: str) -> Table:
    """Exposure starts derived from header stamps again, with this camera's `stamp`.

    The workers derive them with the semantics of the topic's (first) camera; a topic
    shared by cameras whose drivers stamp differently needs each camera's own.
    """
    import numpy as np

    from syncaudit.columns.table import MISSING

    derived = frames["source"] != CAMERA_EXPOSURE  # None (no type) counts as derived
    if not derived.any():
        return frames
    stamp, duration = frames["header_stamp_ns"], frames["exposure_duration_ns"]
    known = (stamp != MISSING) & (duration != MISSING)
    if semantics == "exposure_middle":
        start = np.where(known, stamp - duration // 2, stamp)
    elif semantics == "exposure_end":
        start = np.where(known, stamp - duration, stamp)
    else:
        start = stamp
    return frames.with_columns(
        {"exposure_start_ns": np.where(derived, start, frames["exposure_start_ns"])}
    )


def _readable(camera: str, rows: RowStore) -> tuple[Table, str | None]:
    """The readable rows of one topic as a table, and a warning counting the damaged ones.

    Raises LogReadError where every row is damaged: nothing of that topic can be judged.
    """
    table = rows.table()
    bad = rows.damaged
    if not bad:
        return table, None
    first = bad[0]
    where = f"first at log time {first.log_time_ns / 1e9:.9f} s: {first.reason}"
    if not rows.readable:
        raise LogReadError(
            f"camera {camera}: all {len(bad)} messages on {first.topic} are damaged ({where})"
        )
    noun = "message" if len(bad) == 1 else "messages"
    return table, f"camera {camera}: {len(bad)} damaged {noun} skipped on {first.topic} ({where})"


def _image_table(rows: list[Row]) -> Table:
    """Image rows (ImageRow) as their table."""
    import numpy as np

    from syncaudit.columns.table import Table, int_column

    return Table(
        {
            "header_stamp_ns": np.array([r[0] for r in rows], dtype=np.int64),
            "log_time_ns": np.array([r[1] for r in rows], dtype=np.int64),
            "frame_sequence": int_column(r[2] for r in rows),
            "frame_id": _strings([r[3] for r in rows]),
        },
        len(rows),
    )


def _frame_table(rows: list[Row]) -> Table:
    return _table(rows, FRAME_COLUMNS)


def _trigger_table(rows: list[Row]) -> Table:
    return _table(rows, TRIGGER_COLUMNS)


def _strings(values: list[Any]) -> Any:
    """A string column whose equal values share one str object (names and frame ids repeat
    for every frame: one object each, not one per row)."""
    from syncaudit.columns.table import str_column

    seen: dict[Any, Any] = {}
    return str_column([seen.setdefault(v, v) for v in values])


def _table(rows: list[tuple[Any, ...]], columns: dict[str, str]) -> Table:
    """A typed table from row tuples, built column by column (see columns.table)."""
    import numpy as np

    from syncaudit.columns.table import Table, int_column

    values = list(zip(*rows, strict=True)) if rows else [()] * len(columns)
    out: dict[str, Any] = {}
    for (name, dtype), column in zip(columns.items(), values, strict=True):
        if dtype == "string":
            out[name] = _strings(list(column))
        elif dtype == "Int64":
            out[name] = int_column(column)
        else:
            out[name] = np.array(column, dtype=dtype)
    return Table(out, len(rows))
