"""Where a camera looks, as a LiDAR packet azimuth: from the rig, or from /tf_static."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from syncaudit.logs import LogReader
from syncaudit.rig import CameraConfig, LidarConfig

TF_TYPES = frozenset({"tf2_msgs/msg/TFMessage"})


def _rotate(q: Any, v: tuple[float, float, float]) -> tuple[float, float, float]:
    """Rotate vector v by quaternion q (x, y, z, w)."""
    x, y, z, w = float(q.x), float(q.y), float(q.z), float(q.w)
    u = np.array([x, y, z])
    vec = np.array(v)
    out = 2.0 * np.dot(u, vec) * u + (w * w - np.dot(u, u)) * vec + 2.0 * w * np.cross(u, vec)
    return float(out[0]), float(out[1]), float(out[2])


def tf_static_yaws(log: LogReader) -> dict[str, float]:
    """Yaw (deg, CCW from the parent's +X) of each child frame's viewing axis in /tf_static.

    Optical frames (name containing 'optical') look along +Z, others along +X (REP 103).
    """
    yaws: dict[str, float] = {}
    topics = [t.name for t in log.topics.values() if t.msgtype in TF_TYPES and "static" in t.name]
    for msg in log.messages(topics):
        tf: Any = log.deserialize(msg)
        for transform in tf.transforms:
            child = str(transform.child_frame_id)
            axis = (0.0, 0.0, 1.0) if "optical" in child else (1.0, 0.0, 0.0)
            dx, dy, _ = _rotate(transform.transform.rotation, axis)
            yaws[child] = math.degrees(math.atan2(dy, dx))
    return yaws


def yaw_to_azimuth(yaw_deg: float, lidar: LidarConfig) -> float | None:
    """A yaw in the LiDAR frame as a packet azimuth, where the rig says how they relate."""
    if lidar.azimuth_of_x_axis_deg is None:
        return None
    sign = -1.0 if lidar.azimuth_clockwise_from_above else 1.0
    return (lidar.azimuth_of_x_axis_deg + sign * yaw_deg) % 360.0


def needs_tf_static(cam: CameraConfig) -> bool:
    """True when only /tf_static can say where the camera looks (the rig gives no angle)."""
    return cam.azimuth_deg is None and cam.yaw_deg is None and bool(cam.frame_id)


def camera_azimuth(
    cam: CameraConfig, lidar: LidarConfig, tf_yaws: dict[str, float]
) -> tuple[float | None, str]:
    """The camera centre's packet azimuth and where it came from (or None and why not)."""
    if cam.azimuth_deg is not None:
        return cam.azimuth_deg, "rig azimuth_deg"
    yaw, source = cam.yaw_deg, "rig yaw_deg"
    if yaw is None and cam.frame_id and cam.frame_id in tf_yaws:
        yaw, source = tf_yaws[cam.frame_id], f"/tf_static ({cam.frame_id})"
    if yaw is None:
        return None, "no azimuth_deg, yaw_deg or /tf_static frame for the camera"
    azimuth = yaw_to_azimuth(yaw, lidar)
    if azimuth is None:
        return None, f"yaw from {source} but lidar.azimuth_of_x_axis_deg is not set"
    return azimuth, source
