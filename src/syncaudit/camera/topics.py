"""Which camera topics a log has, by message type, and which camera each belongs to."""

from __future__ import annotations

from collections import defaultdict

from syncaudit.logs import TopicInfo
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
        "time_reference",
    }
)


def camera_name(topic: str) -> str:
    """Guess a camera's name from a topic: the last path part that is not a known leaf."""
    parts = [p for p in topic.split("/") if p]
    while len(parts) > 1 and parts[-1] in _LEAVES:
        parts.pop()
    return parts[-1] if parts else topic


def detect_cameras(topics: dict[str, TopicInfo]) -> list[CameraConfig]:
    """Camera configs guessed from topic types and names (one per camera name)."""
    found: dict[str, dict[str, str]] = defaultdict(dict)
    for info in sorted(topics.values(), key=lambda t: t.name):
        if info.msgtype in IMAGE_TYPES:
            role = "image_topic"
        elif info.msgtype in INFO_TYPES:
            role = "info_topic"
        elif info.msgtype in EXPOSURE_TYPES:
            role = "exposure_topic"
        elif info.msgtype in TRIGGER_TYPES:
            role = "trigger_topic"
        else:
            continue
        slots = found[camera_name(info.name)]
        if role == "image_topic" and role in slots and info.msgtype.endswith("CompressedImage"):
            continue  # keep the raw image where both are recorded
        slots.setdefault(role, info.name)
    cameras = []
    for name, slots in sorted(found.items()):
        if "exposure_topic" in slots and "image_topic" not in slots:
            exposure_type = topics[slots["exposure_topic"]].msgtype
            if exposure_type == "wfov_camera_msgs/msg/WFOVImage":
                slots["image_topic"] = slots["exposure_topic"]
        cameras.append(CameraConfig.model_validate({"name": name, **slots}))
    return cameras
