"""Where a camera looks, as a LiDAR packet azimuth: from the rig, or from /tf_static."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from syncaudit.camera.cdr_fast import read_tf_message
from syncaudit.logs import LogReader
from syncaudit.rig import CameraConfig, LidarConfig

TF_TYPES = frozenset({"tf2_msgs/msg/TFMessage"})

X_AXIS_AZIMUTH_DEG: dict[str, float] = {"velodyne": 0.0, "hesai": 90.0, "ouster": 180.0}
"""Packet azimuth of the +X axis of the frame each vendor's ROS driver publishes in.

All three spin clockwise seen from above (the packet azimuth grows clockwise).
- Velodyne, `velodyne_pointcloud` (`src/lib/rawdata.cc`, `unpack`):
  `x = xy_distance * cos_rot_angle; y = -(xy_distance * sin_rot_angle)`, so +X is at
  azimuth 0 and +Y at 270.
- Hesai, `HesaiLidar` / tier4 `nebula` (`hesai_decoder.hpp`, `convertReturns`):
  `x = xy_distance * sin_azimuth; y = xy_distance * cos_azimuth`, so +X is at azimuth
  90 and +Y at 0.
- Ouster, `ouster-ros` publishes in the sensor frame (`os_sensor`); the encoder angle is 0
  at the lidar frame's +X (Ouster's `theta_encoder = 2 pi (1 - count / 90112)`) and the
  SDK's `default_lidar_to_sensor_transform` is a 180 deg turn about Z
  (`diag(-1, -1, 1)`), so the sensor frame's +X is at encoder angle 180.
A camera mounted on another frame (e.g. `os_lidar`) needs the rig's value instead.
"""


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
        tf: Any = read_tf_message(msg.data, msg.encoding) or log.deserialize(msg)
        for transform in tf.transforms:
            child = str(transform.child_frame_id)
            axis = (0.0, 0.0, 1.0) if "optical" in child else (1.0, 0.0, 0.0)
            dx, dy, _ = _rotate(transform.transform.rotation, axis)
            yaws[child] = math.degrees(math.atan2(dy, dx))
    return yaws


def x_axis_azimuth_deg(lidar: LidarConfig, vendor: str | None = None) -> tuple[float | None, str]:
    """Packet azimuth of the LiDAR frame's +X: the rig's, else the vendor driver's default."""
    if lidar.azimuth_of_x_axis_deg is not None:
        return lidar.azimuth_of_x_axis_deg, "rig"
    vendor = lidar.vendor or vendor
    if vendor in X_AXIS_AZIMUTH_DEG:
        return X_AXIS_AZIMUTH_DEG[vendor], f"{vendor} ROS driver default"
    return None, "unknown vendor"


def yaw_to_azimuth(yaw_deg: float, lidar: LidarConfig, vendor: str | None = None) -> float | None:
    """A yaw in the LiDAR frame as a packet azimuth (None where the +X azimuth is unknown)."""
    x_axis, _ = x_axis_azimuth_deg(lidar, vendor)
    if x_axis is None:
        return None
    sign = -1.0 if lidar.azimuth_clockwise_from_above else 1.0
    return (x_axis + sign * yaw_deg) % 360.0


def needs_tf_static(cam: CameraConfig) -> bool:
    """True when only /tf_static can say where the camera looks (the rig gives no angle)."""
    return cam.azimuth_deg is None and cam.yaw_deg is None and bool(cam.frame_id)


def camera_azimuth(
    cam: CameraConfig, lidar: LidarConfig, tf_yaws: dict[str, float], vendor: str | None = None
) -> tuple[float | None, str]:
    """The camera centre's packet azimuth and where it came from (or None and why not).

    `vendor` ('velodyne', 'hesai', 'ouster', from the packet type) supplies the +X
    azimuth where the rig omits it (`X_AXIS_AZIMUTH_DEG`).
    """
    if cam.azimuth_deg is not None:
        return cam.azimuth_deg, "rig azimuth_deg"
    yaw, source = cam.yaw_deg, "rig yaw_deg"
    if yaw is None and cam.frame_id and cam.frame_id in tf_yaws:
        yaw, source = tf_yaws[cam.frame_id], f"/tf_static ({cam.frame_id})"
    if yaw is None:
        return None, "no azimuth_deg, yaw_deg or /tf_static frame for the camera"
    azimuth = yaw_to_azimuth(yaw, lidar, vendor)
    if azimuth is None:
        return None, f"yaw from {source} but lidar.azimuth_of_x_axis_deg is not set"
    x_axis, x_source = x_axis_azimuth_deg(lidar, vendor)
    if x_source != "rig":
        source = f"{source}, +X at azimuth {x_axis:g} ({x_source})"
    return azimuth, source
