"""Camera frames and triggers of one camera as tables (see syncaudit.columns.camera).

Image headers are read straight from the serialized bytes (the stamp sits at a fixed
offset in both encodings), so large image payloads are never deserialised. Exposure and
trigger messages are small and go through rosbags with the log's own definitions.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

import pandas as pd

from syncaudit.columns.camera import FRAME_COLUMNS, TRIGGER_COLUMNS
from syncaudit.logs import LogReader, RawMessage
from syncaudit.rig import CameraConfig

_STAMP = struct.Struct("<iI")
_STAMP_BE = struct.Struct(">iI")
_ROS1_STAMP = struct.Struct("<II")


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
    return int(struct.unpack_from("<I", msg.data, 0)[0]) if msg.encoding == "ros1" else None


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


def _exposure_start(stamp: int, duration: int | None, semantics: str) -> int:
    """Exposure start from a header stamp and what the stamp marks."""
    if duration is None or semantics in ("exposure_start", "trigger"):
        return stamp
    return stamp - (duration // 2 if semantics == "exposure_middle" else duration)


def read_camera(log: LogReader, cam: CameraConfig) -> CameraTables:
    """Read one camera's image, exposure and trigger topics into tables."""
    images = _read_images(log, cam.image_topic) if cam.image_topic else None
    exposure_rows, exposure_source = _read_exposures(log, cam)
    trigger_rows, trigger_source = _read_triggers(log, cam)
    if images is None:
        images = pd.DataFrame(
            {"header_stamp_ns": pd.Series(dtype="int64"), "log_time_ns": pd.Series(dtype="int64")}
        )
    if exposure_rows:
        frames = pd.DataFrame(exposure_rows, columns=list(FRAME_COLUMNS))
    else:
        assumed = None if cam.assumed_exposure_us is None else int(cam.assumed_exposure_us * 1e3)
        frames = pd.DataFrame(
            {
                "camera": cam.name,
                "frame_sequence": images.get("frame_sequence"),
                "header_stamp_ns": images["header_stamp_ns"],
                "log_time_ns": images["log_time_ns"],
                "exposure_start_ns": [
                    _exposure_start(int(s), assumed, cam.stamp) if assumed else None
                    for s in images["header_stamp_ns"]
                ],
                "exposure_duration_ns": assumed,
                "source": "image" if assumed is None else "image+assumed_exposure",
            },
            columns=list(FRAME_COLUMNS),
        )
    frames = frames.astype(FRAME_COLUMNS).sort_values("log_time_ns", kind="stable")
    triggers = pd.DataFrame(trigger_rows, columns=list(TRIGGER_COLUMNS)).astype(TRIGGER_COLUMNS)
    return CameraTables(
        cam.name,
        images,
        frames.reset_index(drop=True),
        triggers,
        exposure_source,
        trigger_source,
    )


def _read_images(log: LogReader, topic: str) -> pd.DataFrame:
    stamps, times, seqs = [], [], []
    wfov = log.topics[topic].msgtype == "wfov_camera_msgs/msg/WFOVImage"
    for msg in log.messages([topic]):
        stamps.append(header_stamp_ns(msg))
        times.append(msg.log_time_ns)
        seqs.append(_ros1_seq(msg))
    del wfov
    return pd.DataFrame(
        {
            "header_stamp_ns": pd.array(stamps, dtype="int64"),
            "log_time_ns": pd.array(times, dtype="int64"),
            "frame_sequence": pd.array(seqs, dtype="Int64"),
        }
    )


def _read_exposures(log: LogReader, cam: CameraConfig) -> tuple[list[tuple[Any, ...]], str | None]:
    topic = cam.exposure_topic
    if topic is None or topic not in log.topics:
        return [], None
    msgtype = log.topics[topic].msgtype
    rows: list[tuple[Any, ...]] = []
    for msg in log.messages([topic]):
        m: Any = log.deserialize(msg)
        stamp = _time_ns(m.header.stamp)
        seq = _ros1_seq(msg)
        if msgtype == "syncaudit_msgs/msg/CameraExposure":
            start = _time_ns(m.exposure_start)
            duration: int | None = round(float(m.exposure_duration) * 1e9)
            seq = int(m.frame_sequence)
        elif msgtype == "flir_camera_msgs/msg/ImageMetaData":
            duration = int(m.exposure_time) * 1000
            start = _exposure_start(stamp, duration, cam.stamp)
        else:  # wfov_camera_msgs/msg/WFOVImage: shutter in seconds, negative = invalid
            duration = round(float(m.shutter) * 1e9) if float(m.shutter) >= 0 else None
            start = _exposure_start(stamp, duration, cam.stamp)
        rows.append((cam.name, seq, stamp, msg.log_time_ns, start, duration, msgtype))
    return rows, msgtype


def _read_triggers(log: LogReader, cam: CameraConfig) -> tuple[list[tuple[Any, ...]], str | None]:
    topic = cam.trigger_topic
    if topic is None or topic not in log.topics:
        return [], None
    msgtype = log.topics[topic].msgtype
    rows: list[tuple[Any, ...]] = []
    for msg in log.messages([topic]):
        m: Any = log.deserialize(msg)
        if msgtype == "syncaudit_msgs/msg/TriggerEvent":
            rows.append(
                (
                    cam.name,
                    int(m.frame_sequence),
                    msg.log_time_ns,
                    _time_ns(m.lidar_packet_time),
                    _time_ns(m.lidar_driver_time),
                    _time_ns(m.camera_driver_time),
                    _time_ns(m.camera_sensor_time),
                    _time_ns(m.exposure_start_time),
                    round(float(m.applied_delay) * 1e9),
                    msgtype,
                )
            )
        else:
            sent = _time_ns(m) if msgtype == "builtin_interfaces/msg/Time" else _time_ns(m.time_ref)
            rows.append(
                (
                    cam.name,
                    _ros1_seq(msg),
                    msg.log_time_ns,
                    None,
                    None,
                    None,
                    sent,
                    None,
                    None,
                    msgtype,
                )
            )
    return rows, msgtype
