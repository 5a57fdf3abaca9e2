"""The simulator's rigid motions: 4x4 transforms, ROS roll/pitch/yaw, quaternions (x, y, z, w).

Written apart from `syncaudit.calib.se3`, which the calibrator reads `/tf_static` with and
is scored by: were both one code, a quaternion-order or transform-direction mistake would
cancel out between the log the simulator writes and the calibrator's reading of it. The
conventions are pinned by hand-written numbers in tests/simulate/test_rigid.py (and those of
`calib.se3` in tests/calib/test_se3_conventions.py).

Conventions (REP 103): `parent_from_child` maps a point given in the child frame into the
parent frame, p_parent = R p_child + t; roll, pitch, yaw are fixed-axis rotations about x,
y, z applied in that order, R = Rz(yaw) Ry(pitch) Rx(roll); quaternions are (x, y, z, w)
with w >= 0, as geometry_msgs/Quaternion stores them.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]


def transform(rotation: F64, translation_m: F64 | tuple[float, float, float]) -> F64:
    """parent_from_child as a 4x4 matrix: the child's axes `rotation` and origin `translation_m`."""
    out = np.eye(4)
    out[:3, :3] = rotation
    out[:3, 3] = np.asarray(translation_m, dtype=np.float64)
    return out


def inverse(parent_from_child: F64) -> F64:
    """child_from_parent of a rigid transform (rotation transposed, origin moved back)."""
    rotation_t = parent_from_child[:3, :3].T
    out = np.eye(4)
    out[:3, :3] = rotation_t
    out[:3, 3] = -rotation_t @ parent_from_child[:3, 3]
    return out


def yaw_matrix(yaw_rad: float) -> F64:
    """Rotation by `yaw_rad` about z (counter-clockwise seen from above)."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _pitch_matrix(pitch_rad: float) -> F64:
    """Rotation about y (positive pitch turns +x towards -z: nose down)."""
    c, s = math.cos(pitch_rad), math.sin(pitch_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _roll_matrix(roll_rad: float) -> F64:
    """Rotation about x (positive roll turns +y towards +z)."""
    c, s = math.cos(roll_rad), math.sin(roll_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rpy_matrix(roll_rad: float, pitch_rad: float, yaw_rad: float) -> F64:
    """R = Rz(yaw) Ry(pitch) Rx(roll): roll first, about the fixed axes (ROS)."""
    return yaw_matrix(yaw_rad) @ _pitch_matrix(pitch_rad) @ _roll_matrix(roll_rad)


def rpy_of(rotation: F64) -> tuple[float, float, float]:
    """(roll, pitch, yaw) in radians of a rotation, pitch within +-pi/2 (`rpy_matrix` undone)."""
    roll = math.atan2(float(rotation[2, 1]), float(rotation[2, 2]))
    pitch = math.asin(float(np.clip(-rotation[2, 0], -1.0, 1.0)))
    yaw = math.atan2(float(rotation[1, 0]), float(rotation[0, 0]))
    return roll, pitch, yaw


def axis_angle_matrix(rotvec_rad: F64) -> F64:
    """Rotation about the unit axis of `rotvec_rad` by its length (Rodrigues)."""
    angle = float(np.linalg.norm(rotvec_rad))
    if angle < 1e-12:
        x, y, z = (float(v) for v in rotvec_rad)
        return np.asarray(np.eye(3) + np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]))
    x, y, z = (float(v) for v in np.asarray(rotvec_rad, dtype=np.float64) / angle)
    cross = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return np.asarray(
        np.eye(3) + math.sin(angle) * cross + (1.0 - math.cos(angle)) * (cross @ cross)
    )


def quaternion_xyzw(rotation: F64) -> tuple[float, float, float, float]:
    """The unit quaternion (x, y, z, w), w >= 0, of a rotation matrix.

    Shepperd's choice of the largest of w, x, y, z to divide by keeps it exact near 180 deg.
    """
    m = rotation
    trace = float(m[0, 0] + m[1, 1] + m[2, 2])
    if trace > 0:
        s = math.sqrt(trace + 1.0) * 2.0  # 4 w
        q = (float(m[2, 1] - m[1, 2]) / s, float(m[0, 2] - m[2, 0]) / s)
        x, y, z, w = q[0], q[1], float(m[1, 0] - m[0, 1]) / s, 0.25 * s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + float(m[0, 0] - m[1, 1] - m[2, 2])) * 2.0  # 4 x
        x, y = 0.25 * s, float(m[0, 1] + m[1, 0]) / s
        z, w = float(m[0, 2] + m[2, 0]) / s, float(m[2, 1] - m[1, 2]) / s
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + float(m[1, 1] - m[0, 0] - m[2, 2])) * 2.0  # 4 y
        x, y = float(m[0, 1] + m[1, 0]) / s, 0.25 * s
        z, w = float(m[1, 2] + m[2, 1]) / s, float(m[0, 2] - m[2, 0]) / s
    else:
        s = math.sqrt(1.0 + float(m[2, 2] - m[0, 0] - m[1, 1])) * 2.0  # 4 z
        x, y = float(m[0, 2] + m[2, 0]) / s, float(m[1, 2] + m[2, 1]) / s
        z, w = 0.25 * s, float(m[1, 0] - m[0, 1]) / s
    if w < 0:
        return -x, -y, -z, -w
    return x, y, z, w


def difference(reference: F64, other: F64) -> tuple[float, float]:
    """How far `other` is from `reference`: angle (deg) and shift (m) of reference^-1 other."""
    delta = inverse(reference) @ other
    cos_angle = float(np.clip((np.trace(delta[:3, :3]) - 1.0) / 2.0, -1.0, 1.0))
    return math.degrees(math.acos(cos_angle)), float(np.linalg.norm(delta[:3, 3]))
