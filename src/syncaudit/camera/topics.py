"""Which camera topics a log has, by message type, and which camera each belongs to.

Topics are classified by message type first (an image, camera info, exposure or trigger
type), and only then named: the camera of a trigger or exposure record is its `camera`
field where the message has one, else its namespace, so `/cam_front/trigger_event` joins
camera `cam_front` instead of becoming a camera `trigger_event`.
"""

from __future__ import annotations

import struct
from collections import defaultdict
from collections.abc import Iterable
from typing import Any

from syncaudit.logs import LogReader, RawMessage, TopicInfo
from syncaudit.rig import CameraConfig

IMAGE_TYPES = frozenset({"sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"})
INFO_TYPES = frozenset({"sensor_msgs/msg/CameraInfo"})
EXPOSURE_TYPES = frozenset(
    {
        "syncaudit_msgs/msg/CameraExposure",
        "flir_camera_msgs/msg/ImageMetaData",
        "wfov_camera_msgs/msg/WFOVImage",
    }
)
TRIGGER_TYPES = frozenset(
    {
        "syncaudit_msgs/msg/TriggerEvent",
        "builtin_interfaces/msg/Time",
        "sensor_msgs/msg/TimeReference",
    }
)
_LEAVES = frozenset(
    {
        "image",
        "image_raw",
        "image_rect",
        "image_color",
        "image_rect_color",
        "compressed",
        "camera_info",
        "meta",
        "metadata",
        "image_meta",
        "exposure",
        "trigger",
        "trigger_time",
        "trigger_event",
        "trigger_events",
        "time_reference",
        "exposure_info",
        "camera_exposure",
    }
)
CAMERA_FIELD_TYPES = frozenset(
    {"syncaudit_msgs/msg/TriggerEvent", "syncaudit_msgs/msg/CameraExposure"}
)
"""Types whose `camera` field names the camera they belong to."""
_ROLES = (
    (IMAGE_TYPES, "image_topic"),
    (INFO_TYPES, "info_topic"),
    (EXPOSURE_TYPES, "exposure_topic"),
    (TRIGGER_TYPES, "trigger_topic"),
)


def camera_name(topic: str) -> str:
    """Guess a camera's name from a topic: the last path part that is not a known leaf."""
    parts = [p for p in topic.split("/") if p]
    while len(parts) > 1 and parts[-1] in _LEAVES:
        parts.pop()
    return parts[-1] if parts else topic


def topic_role(msgtype: str) -> str | None:
    """The CameraConfig field a topic of this type fills (None: not a camera topic)."""
    for types, role in _ROLES:
        if msgtype in types:
            return role
    return None


def _namespace(topic: str) -> str | None:
    parts = [p for p in topic.split("/") if p]
    while len(parts) > 1 and parts[-1] in _LEAVES:
        parts.pop()
    return parts[-2] if len(parts) > 1 else None


def _owner(info: TopicInfo, role: str, cameras: set[str], camera_fields: dict[str, str]) -> str:
    """The camera a topic belongs to: `camera` field, image camera by name, or namespace."""
    field = camera_fields.get(info.name, "")
    if field:
        return field
    name = camera_name(info.name)
    if role in ("exposure_topic", "trigger_topic") and name not in cameras:
        namespace = _namespace(info.name)
        if namespace is not None and namespace in cameras:
            return namespace
    return name


def detect_cameras(
    topics: dict[str, TopicInfo],
    camera_fields: dict[str, str] | None = None,
    frame_ids: dict[str, str] | None = None,
) -> list[CameraConfig]:
    """Camera configs guessed from topic types, then names (one per camera name).

    `camera_fields` maps trigger/exposure topics to the `camera` field of their first
    message, `frame_ids` image topics to their header frame (see `probe_camera_topics`).
    """
    camera_fields = camera_fields or {}
    frame_ids = frame_ids or {}
    roles = {
        info.name: role
        for info in topics.values()
        if (role := topic_role(info.msgtype)) is not None
    }
    image_cameras = {camera_name(t) for t, r in roles.items() if r in ("image_topic", "info_topic")}
    found: dict[str, dict[str, str]] = defaultdict(dict)
    for name in sorted(roles):
        info, role = topics[name], roles[name]
        slots = found[_owner(info, role, image_cameras, camera_fields)]
        if role == "image_topic" and role in slots and info.msgtype.endswith("CompressedImage"):
            continue  # keep the raw image where both are recorded
        slots.setdefault(role, info.name)
    cameras = []
    for name, slots in sorted(found.items()):
        if "exposure_topic" in slots and "image_topic" not in slots:
            exposure_type = topics[slots["exposure_topic"]].msgtype
            if exposure_type == "wfov_camera_msgs/msg/WFOVImage":
                slots["image_topic"] = slots["exposure_topic"]
        frame = frame_ids.get(slots.get("image_topic", "")) or frame_ids.get(
            slots.get("info_topic", "")
        )
        fields: dict[str, Any] = {"name": name, **slots}
        if frame:
            fields["frame_id"] = frame
        cameras.append(CameraConfig.model_validate(fields))
    return cameras


_U32 = struct.Struct("<I")
_U32_BE = struct.Struct(">I")


def header_frame_id(msg: RawMessage) -> str:
    """`header.frame_id` of a message whose first field is a std_msgs/Header (raw bytes).

    "" where the bytes are too short to hold one (a guess, never an error).
    """
    data = bytes(msg.data[:4096])
    if msg.encoding == "ros1":
        offset, unpack = 12, _U32.unpack_from  # seq, stamp
    else:
        little = data[1:2] in (b"\x01", b"\x03")
        offset, unpack = 12, (_U32 if little else _U32_BE).unpack_from  # encapsulation, stamp
    try:
        (length,) = unpack(data, offset)
    except struct.error:
        return ""
    text = data[offset + 4 : offset + 4 + length]
    return text.rstrip(b"\x00").decode("utf-8", errors="replace")


PROBE_WINDOW_NS = 60_000_000_000
"""Only the log's first minute is searched for each camera topic's first message."""


def probe_camera_topics(
    log: LogReader, topics: Iterable[str]
) -> tuple[dict[str, str], dict[str, str]]:
    """From the first message of each camera topic: `camera` fields and image frame ids.

    Reads only until every topic has shown one message, and at most the log's first
    minute (topics without messages, or starting later, are left out).
    """
    probed = CAMERA_FIELD_TYPES | IMAGE_TYPES | INFO_TYPES
    pending = {
        t
        for t in topics
        if t in log.topics and log.topics[t].msgtype in probed and log.topics[t].count != 0
    }
    camera_fields: dict[str, str] = {}
    frame_ids: dict[str, str] = {}
    if not pending:
        return camera_fields, frame_ids
    start = log.summary.start_ns
    stop = None if start is None else start + PROBE_WINDOW_NS
    for msg in log.messages(sorted(pending), stop_ns=stop):
        if msg.topic not in pending:
            continue
        pending.discard(msg.topic)
        if msg.msgtype in CAMERA_FIELD_TYPES:
            camera_fields[msg.topic] = str(getattr(log.deserialize(msg), "camera", ""))
        else:
            frame_ids[msg.topic] = header_frame_id(msg)
        if not pending:
            break
    return camera_fields, frame_ids
