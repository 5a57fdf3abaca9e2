"""Which camera topics a log has, by message type, and which camera each belongs to.

Topics are classified by message type first (an image, camera info, exposure or trigger
type), and only then named: the camera of a trigger or exposure record is its `camera`
field where the message has one, else its namespace, so `/cam_front/trigger_event` joins
camera `cam_front` instead of becoming a camera `trigger_event`.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from syncaudit.camera.cdr_fast import read_fast
from syncaudit.camera.extract import CAMERA_FIELD_TYPES, header_frame_id
from syncaudit.logs import LogReader, RawMessage, TopicInfo
from syncaudit.rig import CameraConfig

__all__ = [
    "CAMERA_FIELD_TYPES",
    "CameraProbe",
    "camera_name",
    "detect_cameras",
    "frame_camera_name",
    "header_frame_id",
    "probe_camera_topics",
    "topic_role",
]
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


MAX_SHARED_CAMERAS = 16
"""More frame ids than this on one image topic within the probe window are not cameras
(drivers exist that put a per-image id in frame_id): the topic stays one camera."""
_FRAME_SUFFIXES = ("_optical_frame", "_optical", "_frame", "_link")


def frame_camera_name(frame_id: str) -> str:
    """A camera name from a frame id: `cam_front_optical_frame` -> `cam_front`."""
    name = frame_id.strip("/").rsplit("/", 1)[-1]
    for suffix in _FRAME_SUFFIXES:
        if name.endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)]
    return name or frame_id


def detect_cameras(
    topics: dict[str, TopicInfo],
    camera_fields: dict[str, str] | None = None,
    frame_ids: dict[str, str] | None = None,
    shared: dict[str, list[str]] | None = None,
) -> list[CameraConfig]:
    """Camera configs guessed from topic types, then names (one per camera name).

    `camera_fields` maps trigger/exposure topics to the `camera` field of their first
    message, `frame_ids` image topics to their header frame, `shared` topics to the
    several cameras their messages name (frame ids of an image topic, `camera` fields of
    a trigger/exposure topic; see `probe_camera_topics`). An image topic of several frame
    ids is several cameras, one per frame id, sharing it and its namespace's other topics.
    """
    camera_fields = camera_fields or {}
    frame_ids = frame_ids or {}
    shared = {t: ids for t, ids in (shared or {}).items() if 1 < len(ids) <= MAX_SHARED_CAMERAS}
    # A shared trigger/exposure topic belongs to its namespace, not to its first message's camera.
    fields_of = {t: f for t, f in camera_fields.items() if t not in shared}
    roles = {
        info.name: role
        for info in topics.values()
        if (role := topic_role(info.msgtype)) is not None
    }
    image_cameras = {camera_name(t) for t, r in roles.items() if r in ("image_topic", "info_topic")}
    found: dict[str, dict[str, str]] = defaultdict(dict)
    for name in sorted(roles):
        info, role = topics[name], roles[name]
        slots = found[_owner(info, role, image_cameras, fields_of)]
        if role == "image_topic" and role in slots and info.msgtype.endswith("CompressedImage"):
            continue  # keep the raw image where both are recorded
        slots.setdefault(role, info.name)
    cameras: list[CameraConfig] = []
    for name, slots in sorted(found.items()):
        if "exposure_topic" in slots and "image_topic" not in slots:
            exposure_type = topics[slots["exposure_topic"]].msgtype
            if exposure_type == "wfov_camera_msgs/msg/WFOVImage":
                slots["image_topic"] = slots["exposure_topic"]
        frame_topic = slots.get("image_topic") or slots.get("info_topic", "")
        if frame_topic in shared:
            taken = {c.name for c in cameras}
            for frame in shared[frame_topic]:
                split = frame_camera_name(frame)
                split = split if split not in taken else frame
                taken.add(split)
                cameras.append(
                    CameraConfig.model_validate({"name": split, **slots, "frame_id": frame})
                )
            continue
        first_frame = frame_ids.get(slots.get("image_topic", "")) or frame_ids.get(
            slots.get("info_topic", "")
        )
        fields: dict[str, Any] = {"name": name, **slots}
        if first_frame:
            fields["frame_id"] = first_frame
        cameras.append(CameraConfig.model_validate(fields))
    return cameras


PROBE_WINDOW_NS = 60_000_000_000
"""Only the log's first minute is searched for each camera topic's first message."""
SHARED_WINDOW_NS = 1_000_000_000
"""After a topic's first message, this long is read for other cameras on it: one frame
of each camera of a shared topic (cameras run at 1 Hz or more)."""


@dataclass(frozen=True, slots=True)
class CameraProbe:
    """What the first messages of the camera topics say about their cameras."""

    camera_fields: dict[str, str]
    """Trigger/exposure topic -> `camera` field of its first message."""
    frame_ids: dict[str, str]
    """Image/info topic -> header.frame_id of its first message."""
    shared: dict[str, list[str]]
    """Topic -> the distinct non-empty names (frame ids, or camera fields) its messages gave
    in `SHARED_WINDOW_NS`, where there were several."""


def _camera_fields(log: LogReader, msg: RawMessage) -> object:
    """A syncaudit camera message's fields: by struct where it fits its layout (no type
    registry to build from the log's schemas), else through rosbags (which raises on
    damaged bytes, as the probe always has)."""
    fields = read_fast(msg.data, msg.msgtype, msg.encoding)
    if fields is None or hasattr(fields, "damaged"):
        return log.deserialize(msg)
    return fields


def probe_camera_topics(log: LogReader, topics: Iterable[str]) -> CameraProbe:
    """From the first second of each camera topic: `camera` fields and image frame ids.

    Reads each topic from its first message for `SHARED_WINDOW_NS` (to see every camera
    of a shared topic), and at most the log's first minute (topics without messages, or
    starting later, are left out).
    """
    probed = CAMERA_FIELD_TYPES | IMAGE_TYPES | INFO_TYPES
    pending = {
        t
        for t in topics
        if t in log.topics and log.topics[t].msgtype in probed and log.topics[t].count != 0
    }
    seen: dict[str, list[str]] = {}
    first_ns: dict[str, int] = {}
    if pending:
        start = log.summary.start_ns
        stop = None if start is None else start + PROBE_WINDOW_NS
        for msg in log.messages(sorted(pending), stop_ns=stop):
            if msg.topic not in pending:
                continue
            first = first_ns.setdefault(msg.topic, msg.log_time_ns)
            if msg.log_time_ns - first > SHARED_WINDOW_NS:
                pending.discard(msg.topic)
                if not pending:
                    break
                continue
            if msg.msgtype in CAMERA_FIELD_TYPES:
                name = str(getattr(_camera_fields(log, msg), "camera", ""))
            else:
                name = header_frame_id(msg)
            names = seen.setdefault(msg.topic, [])
            if name not in names and (name or not names):
                names.append(name)
    firsts = {t: names[0] for t, names in seen.items()}
    return CameraProbe(
        camera_fields={
            t: n for t, n in firsts.items() if log.topics[t].msgtype in CAMERA_FIELD_TYPES
        },
        frame_ids={
            t: n for t, n in firsts.items() if log.topics[t].msgtype not in CAMERA_FIELD_TYPES
        },
        shared={
            t: [n for n in names if n]
            for t, names in seen.items()
            if len([n for n in names if n]) > 1
        },
    )
