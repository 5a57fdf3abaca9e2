"""A rig guessed from what a log holds, and a starter rig file that states every guess.

The LiDAR topic is the first packet topic by type; cameras come from topic types, their
trigger/exposure `camera` fields and namespaces (`camera.topics.detect_cameras`), and
each camera's frame from its image header, so `/tf_static` can place it. The starter
file writes that rig as YAML with a comment on every guessed value and a TODO on every
value the log cannot tell, so the second run is one edit away.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from syncaudit.audit.probe import LogProbe, probe_of
from syncaudit.camera.azimuth import X_AXIS_AZIMUTH_DEG, camera_azimuth, needs_tf_static
from syncaudit.camera.camera_topics import detect_cameras
from syncaudit.errors import NoDataError
from syncaudit.lidar.cloud_topics import guess_cloud_topics
from syncaudit.logs import LogReader, open_log
from syncaudit.rig import CameraConfig, LidarConfig, Rig, Thresholds

__all__ = ["guess_cameras", "guess_rig", "render_starter_rig", "starter_rig_yaml"]


def guess_rig(log: LogReader | LogProbe) -> tuple[Rig, list[str]]:
    """A rig from the log alone, and what was guessed (raises NoDataError without LiDAR)."""
    probe = probe_of(log)
    # The guess `info` shares: IMU packet topics of the same type are set aside.
    lidar_guess = probe.lidar_guess()
    packet_topics = lidar_guess.topics
    how = "by type"
    x_axis: float | None = None
    if not packet_topics:
        clouds = guess_cloud_topics(probe.log)
        packet_topics = clouds.topics
        if packet_topics:
            x_axis = clouds.x_axis_deg[packet_topics[0]]
            how = f"PointCloud2 with per-point {clouds.time_fields[packet_topics[0]]}"
            if x_axis is not None:
                how += f"; its +X at azimuth {x_axis:g} deg, measured from its points"
    if not packet_topics:
        raise NoDataError(
            f"{probe.log.summary.path}: no LiDAR packet topic (known packet types) and no "
            "PointCloud2 with per-point times in the log"
        )
    cameras, camera_notes = guess_cameras(probe)
    guessed = [f"LiDAR topic {packet_topics[0]} ({how})", *lidar_guess.notes, *camera_notes]
    lidar = LidarConfig(topic=packet_topics[0], azimuth_of_x_axis_deg=x_axis)
    return Rig(lidar=lidar, cameras=cameras), guessed


def guess_cameras(log: LogReader | LogProbe) -> tuple[list[CameraConfig], list[str]]:
    """The cameras of a log without a rig, and what was guessed (`audit` and `info` share it).

    Topic types and names give the cameras; the first second of each camera topic gives
    `camera` fields and frame ids, and an image topic of several frame ids is one camera
    per frame id.
    """
    probe = probe_of(log)
    seen = probe.camera_topics()
    cameras = detect_cameras(probe.topics, seen.camera_fields, seen.frame_ids, seen.shared)
    guessed = []
    if cameras:
        guessed.append(
            "cameras " + ", ".join(c.name for c in cameras) + " (by topic type and name)"
        )
    for topic, names in sorted(seen.shared.items()):
        guessed.append(f"{topic} shared by {len(names)} cameras ({', '.join(names)})")
    return cameras, guessed


def _value(value: object) -> str:
    """A YAML scalar (JSON is valid YAML for strings, numbers, booleans and null)."""
    return json.dumps(value)


def _camera_lines(
    cam: CameraConfig, lidar: LidarConfig, tf_yaws: dict[str, float], vendor: str | None
) -> list[str]:
    lines = [f"  - name: {_value(cam.name)}  # guessed from the topic names"]
    for key in ("image_topic", "info_topic", "exposure_topic", "trigger_topic"):
        topic = getattr(cam, key)
        if topic is not None:
            lines.append(f"    {key}: {_value(topic)}  # found by message type")
        elif key in ("exposure_topic", "trigger_topic"):
            lines.append(f"    # {key}: TODO none found; without it some latencies are unknown")
    azimuth, source = camera_azimuth(cam, lidar, tf_yaws, vendor)
    if cam.frame_id:
        lines.append(f"    frame_id: {_value(cam.frame_id)}  # from the image header")
    if azimuth is not None:
        lines.append(
            f"    # azimuth_deg: {azimuth:.2f}  # what the audit will use: {source}; "
            "set it to override"
        )
    else:
        lines.append(
            f"    azimuth_deg: null  # TODO packet azimuth of the camera centre ({source})"
        )
    lines += [
        "    hfov_deg: 90.0  # TODO the camera's horizontal field of view",
        f"    stamp: {cam.stamp}  # TODO what the image header stamp marks in your driver "
        "(exposure_start, exposure_middle, exposure_end, trigger)",
        "    optional: false  # true: a camera that cannot be judged does not fail --gate",
    ]
    return lines


def render_starter_rig(log: LogReader | LogProbe) -> str:
    """The starter rig of an open log as commented YAML (loads as a valid rig)."""
    probe = probe_of(log)
    rig, _ = guess_rig(probe)
    lidar = rig.lidar
    vendor = probe.family(lidar.topic)
    tf_yaws = probe.tf_yaws() if any(needs_tf_static(c) for c in rig.cameras) else {}
    x_axis = X_AXIS_AZIMUTH_DEG.get(vendor or "")
    cloud = vendor is None and lidar.azimuth_of_x_axis_deg is not None
    if cloud:
        x_axis = lidar.azimuth_of_x_axis_deg
    lines = [
        f"# Starter rig for {probe.log.summary.path}, written by `syncaudit rig`.",
        "# Every value below was guessed from the log; check each TODO, then run",
        "#   syncaudit audit LOG --rig THIS_FILE",
        "lidar:",
        f"  topic: {_value(lidar.topic)}  # the first LiDAR packet topic (by message type)"
        if not cloud
        else f"  topic: {_value(lidar.topic)}  # a PointCloud2 with per-point times "
        "(no packet topic in the log)",
        f"  vendor: {_value(vendor)}  # from the packet message type"
        if not cloud
        else "  vendor: null  # TODO the LiDAR's vendor (a point cloud does not say)",
        "  # zero_azimuth_deg: TODO packet azimuth at which the trigger chain fires; while",
        "  #   it is not set, the audit starts revolutions where the triggers fire and says",
        "  #   which azimuth that is in a warning",
        "  azimuth_increases: true  # packet azimuth grows with rotation (all supported vendors)",
    ]
    if x_axis is None:
        lines.append("  azimuth_of_x_axis_deg: null  # TODO packet azimuth of the LiDAR frame's +X")
    elif cloud:
        lines.append(
            f"  azimuth_of_x_axis_deg: {x_axis:g}  # measured from the first cloud's "
            "points (docs/clouds.md)"
        )
    else:
        lines.append(
            f"  azimuth_of_x_axis_deg: {x_axis:g}  # the {vendor} ROS driver's frame "
            "convention; change it if your cameras are mounted on another frame"
        )
    lines.append("cameras:" if rig.cameras else "cameras: []  # TODO no camera topic found")
    for cam in rig.cameras:
        lines += _camera_lines(cam, lidar, tf_yaws, vendor)
    defaults = Thresholds()
    lines.append("thresholds:  # the defaults; see schemas/rig.schema.json")
    for key, value in defaults.model_dump().items():
        number = value if not isinstance(value, float) or math.isfinite(value) else None
        lines.append(f"  {key}: {_value(number)}")
    return "\n".join(lines) + "\n"


def starter_rig_yaml(path: str | Path, lidar_metadata: str | Path | None = None) -> str:
    """The starter rig of the log at `path` (see `render_starter_rig`).

    Raises:
        LogOpenError, LogReadError: the log cannot be read.
        NoDataError: the log has no LiDAR packet topic.
    """
    with open_log(path, lidar_metadata=lidar_metadata) as log:
        return render_starter_rig(log)
