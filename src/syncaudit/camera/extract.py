"""Camera frames and triggers as tables (see syncaudit.columns.camera), one message at a time.

Image headers are read straight from the serialized bytes (the stamp sits at a fixed
offset in both encodings), so large image payloads are never deserialised. Exposure and
trigger messages are small and go through rosbags with the log's own definitions.
The row functions are pure (message in, tuple out) so worker processes can run them.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from syncaudit.columns.camera import FRAME_COLUMNS, TRIGGER_COLUMNS
from syncaudit.logs import RawMessage
from syncaudit.rig import CameraConfig

if TYPE_CHECKING:
    import pandas as pd

_STAMP = struct.Struct("<iI")
_STAMP_BE = struct.Struct(">iI")
_ROS1_STAMP = struct.Struct("<II")
_ROS1_SEQ = struct.Struct("<I")

Deserialize = Callable[[RawMessage], Any]
ImageRow = tuple[int, int, int | None]
"""(header stamp ns, log time ns, ROS 1 seq or None)."""


def header_stamp_ns(msg: RawMessage) -> int:
    """std_msgs/Header stamp of a message whose first field is the header."""
    data = msg.data
    if msg.encoding == "ros1":
        sec, nsec = _ROS1_STAMP.unpack_from(data, 4)
    else:
        little = bytes(data[1:2]) in (b"\x01", b"\x03")
        sec, nsec = (_STAMP if little else _STAMP_BE).unpack_from(data, 4)
    return int(sec) * 1_000_000_000 + int(nsec)


def _time_ns(t: Any) -> int:
    return int(t.sec) * 1_000_000_000 + int(t.nanosec)


def _ros1_seq(msg: RawMessage) -> int | None:
    return int(_ROS1_SEQ.unpack_from(msg.data, 0)[0]) if msg.encoding == "ros1" else None


def exposure_start_ns(stamp: int, duration: int | None, semantics: str) -> int:
    """Exposure start from a header stamp and what the stamp marks."""
    if duration is None or semantics in ("exposure_start", "trigger"):
        return stamp
    return stamp - (duration // 2 if semantics == "exposure_middle" else duration)


def image_row(msg: RawMessage) -> ImageRow:
    """The header of an image (or CameraInfo / WFOVImage) message."""
    return header_stamp_ns(msg), msg.log_time_ns, _ros1_seq(msg)


def exposure_row(msg: RawMessage, m: Any, camera: str, semantics: str) -> tuple[Any, ...]:
    """A FRAME_COLUMNS row from one deserialised exposure message."""
    stamp = _time_ns(m.header.stamp)
    seq = _ros1_seq(msg)
    duration: int | None
    if msg.msgtype == "syncaudit_msgs/msg/CameraExposure":
        start = _time_ns(m.exposure_start)
        duration = round(float(m.exposure_duration) * 1e9)
        seq = int(m.frame_sequence)
    elif msg.msgtype == "flir_camera_msgs/msg/ImageMetaData":
        duration = int(m.exposure_time) * 1000
        start = exposure_start_ns(stamp, duration, semantics)
    else:  # wfov_camera_msgs/msg/WFOVImage: shutter in seconds, negative = invalid
        duration = round(float(m.shutter) * 1e9) if float(m.shutter) >= 0 else None
        start = exposure_start_ns(stamp, duration, semantics)
    return (camera, seq, stamp, msg.log_time_ns, start, duration, msg.msgtype)


def trigger_row(msg: RawMessage, m: Any, camera: str) -> tuple[Any, ...]:
    """A TRIGGER_COLUMNS row from one deserialised trigger message."""
    if msg.msgtype == "syncaudit_msgs/msg/TriggerEvent":
        return (
            camera,
            int(m.frame_sequence),
            msg.log_time_ns,
            _time_ns(m.lidar_packet_time),
            _time_ns(m.lidar_driver_time),
            _time_ns(m.camera_driver_time),
            _time_ns(m.camera_sensor_time),
            _time_ns(m.exposure_start_time),
            round(float(m.applied_delay) * 1e9),
            msg.msgtype,
        )
    sent = _time_ns(m) if msg.msgtype == "builtin_interfaces/msg/Time" else _time_ns(m.time_ref)
    return (
        camera,
        _ros1_seq(msg),
        msg.log_time_ns,
        None,
        None,
        None,
        sent,
        None,
        None,
        msg.msgtype,
    )


@dataclass(frozen=True, slots=True)
class CameraTables:
    """Everything one camera's topics say, as tables."""

    name: str
    images: pd.DataFrame
    """header_stamp_ns, log_time_ns, frame_sequence (ROS 1 seq) of every image."""
    frames: pd.DataFrame
    """FRAME_COLUMNS: one row per exposure record (or per image where there are none)."""
    triggers: pd.DataFrame
    """TRIGGER_COLUMNS."""
    exposure_source: str | None
    trigger_source: str | None


@dataclass(slots=True)
class CameraTableBuilder:
    """Collects one camera's rows as they stream by, then builds its tables."""

    camera: CameraConfig
    images: list[ImageRow] = field(default_factory=list)
    exposures: list[tuple[Any, ...]] = field(default_factory=list)
    triggers: list[tuple[Any, ...]] = field(default_factory=list)

    def build(self) -> CameraTables:
        """The camera's frame, image and trigger tables."""
        import pandas as pd  # deferred: worker processes extract rows without pandas

        cam = self.camera
        images = pd.DataFrame(
            {
                "header_stamp_ns": pd.array([r[0] for r in self.images], dtype="int64"),
                "log_time_ns": pd.array([r[1] for r in self.images], dtype="int64"),
                "frame_sequence": pd.array([r[2] for r in self.images], dtype="Int64"),
            }
        )
        if self.exposures:
            frames = _table(self.exposures, FRAME_COLUMNS)
        else:
            assumed = (
                None if cam.assumed_exposure_us is None else round(cam.assumed_exposure_us * 1e3)
            )
            frames = pd.DataFrame(
                {
                    "camera": cam.name,
                    "frame_sequence": images["frame_sequence"],
                    "header_stamp_ns": images["header_stamp_ns"],
                    "log_time_ns": images["log_time_ns"],
                    "exposure_start_ns": [
                        exposure_start_ns(int(s), assumed, cam.stamp) if assumed else None
                        for s in images["header_stamp_ns"]
                    ],
                    "exposure_duration_ns": assumed,
                    "source": "image" if assumed is None else "image+assumed_exposure",
                },
                columns=list(FRAME_COLUMNS),
            )
        frames = frames.astype(FRAME_COLUMNS).sort_values("log_time_ns", kind="stable")
        triggers = _table(self.triggers, TRIGGER_COLUMNS)
        return CameraTables(
            cam.name,
            images,
            frames.reset_index(drop=True),
            triggers,
            self.exposures[0][-1] if self.exposures else None,
            self.triggers[0][-1] if self.triggers else None,
        )


def _table(rows: list[tuple[Any, ...]], columns: dict[str, Any]) -> pd.DataFrame:
    """A typed table from row tuples, built column by column (3x faster than astype)."""
    import pandas as pd

    values = list(zip(*rows, strict=True)) if rows else [()] * len(columns)
    return pd.DataFrame(
        {
            name: pd.array(list(column), dtype=dtype)
            for (name, dtype), column in zip(columns.items(), values, strict=True)
        }
    )
