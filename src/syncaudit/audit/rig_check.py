"""Where a rig (given or guessed) contradicts or cannot use the log it is applied to.

Two checks run before any message is read:
- encodings: only `cdr` (ROS 2) and `ros1` messages can be read. A camera topic in
  another encoding (`protobuf`, `json`, `cdr2`, none) is dropped from its camera with a
  warning, so the audit of the rest goes on; the LiDAR topic in one is UnknownTypeError
  (exit 4), since without it there is nothing to audit.
- vendor: `lidar.vendor` in the rig must be what the packets are. The message type says
  so for Velodyne, Hesai and Ouster types; Nebula packets are decoded from the first
  scan message (`LogProbe.packet_vendor`, read once). A contradiction is ConfigError (exit 6) naming the key.

And one limit: a rig lists at most `MAX_CAMERAS` cameras (ConfigError otherwise). The
audit is linear in cameras, but each costs ~10-20 ms of table building and analysis
(pandas), so a rig of thousands (a generated or corrupted one; real rigs have a dozen)
would run for minutes; it is refused at once instead.
"""

from __future__ import annotations

from typing import Any

from syncaudit.audit.probe import LogProbe, probe_of
from syncaudit.errors import ConfigError, UnknownTypeError
from syncaudit.logs import LogReader
from syncaudit.rig import Rig

READABLE_ENCODINGS = ("cdr", "ros1")
"""Message encodings syncaudit deserialises (ROS 2 CDR and ROS 1)."""
CAMERA_TOPIC_FIELDS = ("image_topic", "info_topic", "exposure_topic", "trigger_topic")
MAX_CAMERAS = 256
"""Cameras one rig may list (real rigs: up to a few dozen)."""


def unreadable_encoding(log: LogReader | LogProbe, topic: str) -> str | None:
    """Why `topic` cannot be read for its encoding, or None where it can (or is absent)."""
    info = log.topics.get(topic)
    if info is None or info.encoding in READABLE_ENCODINGS:
        return None
    encoding = repr(info.encoding) if info.encoding else "no encoding"
    return f"{topic}: message encoding {encoding} is not ROS (cdr/ros1); syncaudit cannot read it"


def check_rig_against_log(log: LogReader | LogProbe, rig: Rig) -> tuple[Rig, list[str]]:
    """The rig with the camera topics the log cannot be read for removed, and warnings.

    Raises UnknownTypeError where the LiDAR topic's encoding is unreadable and
    ConfigError where `lidar.vendor` contradicts the packets or the rig lists more than
    `MAX_CAMERAS` cameras.
    """
    probe = probe_of(log)
    if len(rig.cameras) > MAX_CAMERAS:
        raise ConfigError(
            f"cameras: the rig lists {len(rig.cameras)} cameras; syncaudit audits at most "
            f"{MAX_CAMERAS} per rig (each costs ~10-20 ms of analysis); split the rig"
        )
    lidar_problem = unreadable_encoding(probe, rig.lidar.topic)
    if lidar_problem is not None:
        raise UnknownTypeError(f"LiDAR topic {lidar_problem}")
    if rig.lidar.vendor is not None:
        found = probe.packet_vendor(rig.lidar.topic)
        if found is not None and found != rig.lidar.vendor:
            msgtype = probe.topics[rig.lidar.topic].msgtype
            raise ConfigError(
                f"lidar.vendor: the rig says {rig.lidar.vendor!r} but {rig.lidar.topic} "
                f"carries {found} packets ({msgtype}); fix or remove the key"
            )
    warnings: list[str] = []
    cameras = []
    for cam in rig.cameras:
        update: dict[str, Any] = {}
        for name in CAMERA_TOPIC_FIELDS:
            topic = getattr(cam, name)
            problem = unreadable_encoding(probe, topic) if topic else None
            if problem is not None:
                update[name] = None
                warnings.append(f"camera {cam.name}: {problem}; topic skipped")
        cameras.append(cam.model_copy(update=update) if update else cam)
    if not warnings:
        return rig, []
    return rig.model_copy(update={"cameras": cameras}), warnings
