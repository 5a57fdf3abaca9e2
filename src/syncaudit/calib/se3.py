"""Rigid-transform helpers on 4x4 numpy matrices (numpy only, so the simulator needs no extra)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

Mat = NDArray[np.float64]


def make_transform(rotation: Mat, translation_m: Mat | tuple[float, float, float]) -> Mat:
    """Build a 4x4 homogeneous transform from a 3x3 rotation and a translation in metres."""
    out = np.eye(4)
    out[:3, :3] = rotation
    out[:3, 3] = np.asarray(translation_m, dtype=np.float64)
    return out


def invert(transform: Mat) -> Mat:
    """Inverse of a rigid transform (uses the rotation's transpose, not a general inverse)."""
    rot = transform[:3, :3]
    out = np.eye(4)
    out[:3, :3] = rot.T
    out[:3, 3] = -rot.T @ transform[:3, 3]
    return out


def apply(transform: Mat, points: NDArray[Any]) -> Mat:
    """Apply a 4x4 transform to an (N, 3) array of points (result in float64)."""
    return np.asarray(points @ transform[:3, :3].T + transform[:3, 3], dtype=np.float64)


def skew(vec: Mat) -> Mat:
    """Cross-product matrix of a 3-vector."""
    x, y, z = (float(v) for v in vec)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def exp_so3(rotvec_rad: Mat) -> Mat:
    """Rotation matrix of a rotation vector (axis times angle in radians), Rodrigues' formula."""
    rotvec = np.asarray(rotvec_rad, dtype=np.float64)
    angle = float(np.linalg.norm(rotvec))
    if angle < 1e-12:
        return np.eye(3) + skew(rotvec)
    k = skew(rotvec / angle)
    return np.asarray(np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k))


def log_so3(rotation: Mat) -> Mat:
    """Rotation vector (radians) of a rotation matrix; stable near 0 and near pi."""
    cos_angle = float(np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0))
    angle = math.acos(cos_angle)
    if angle < 1e-7:
        return 0.5 * np.array(
            [
                rotation[2, 1] - rotation[1, 2],
                rotation[0, 2] - rotation[2, 0],
                rotation[1, 0] - rotation[0, 1],
            ]
        )
    if math.pi - angle < 1e-4:
        # Near pi the antisymmetric part vanishes: take the axis from the symmetric part.
        sym = (rotation + np.eye(3)) / 2.0
        col = int(np.argmax(np.diag(sym)))
        axis = sym[:, col] / math.sqrt(max(sym[col, col], 1e-12))
        return np.asarray(axis / np.linalg.norm(axis) * angle)
    vee = np.array(
        [
            rotation[2, 1] - rotation[1, 2],
            rotation[0, 2] - rotation[2, 0],
            rotation[1, 0] - rotation[0, 1],
        ]
    )
    return np.asarray(vee * (angle / (2.0 * math.sin(angle))))


def rotation_angle_deg(rotation: Mat) -> float:
    """Angle of a rotation matrix in degrees (0..180)."""
    cos_angle = float(np.clip((np.trace(rotation[:3, :3]) - 1.0) / 2.0, -1.0, 1.0))
    return math.degrees(math.acos(cos_angle))


def rot_x(angle_rad: float) -> Mat:
    """Rotation about x."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle_rad: float) -> Mat:
    """Rotation about y."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle_rad: float) -> Mat:
    """Rotation about z."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rpy_to_matrix(roll_rad: float, pitch_rad: float, yaw_rad: float) -> Mat:
    """ROS convention (fixed-axis roll, pitch, yaw): R = Rz(yaw) Ry(pitch) Rx(roll)."""
    return rot_z(yaw_rad) @ rot_y(pitch_rad) @ rot_x(roll_rad)


def matrix_to_rpy(rotation: Mat) -> tuple[float, float, float]:
    """Inverse of `rpy_to_matrix`, radians."""
    pitch = math.asin(float(np.clip(-rotation[2, 0], -1.0, 1.0)))
    roll = math.atan2(float(rotation[2, 1]), float(rotation[2, 2]))
    yaw = math.atan2(float(rotation[1, 0]), float(rotation[0, 0]))
    return roll, pitch, yaw


def quaternion_to_matrix(x: float, y: float, z: float, w: float) -> Mat:
    """Rotation matrix of a (normalised here) quaternion given as x, y, z, w."""
    q = np.array([x, y, z, w], dtype=np.float64)
    norm = float(np.linalg.norm(q))
    if norm < 1e-12:
        raise ValueError("zero-length quaternion")
    x, y, z, w = (float(v) for v in q / norm)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_to_quaternion(rotation: Mat) -> tuple[float, float, float, float]:
    """Quaternion (x, y, z, w, with w >= 0) of a rotation matrix."""
    m = rotation
    trace = float(m[0, 0] + m[1, 1] + m[2, 2])
    if trace > 0:
        s = math.sqrt(trace + 1.0) * 2.0
        w, x = 0.25 * s, float(m[2, 1] - m[1, 2]) / s
        y, z = float(m[0, 2] - m[2, 0]) / s, float(m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + float(m[0, 0] - m[1, 1] - m[2, 2])) * 2.0
        w, x = float(m[2, 1] - m[1, 2]) / s, 0.25 * s
        y, z = float(m[0, 1] + m[1, 0]) / s, float(m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + float(m[1, 1] - m[0, 0] - m[2, 2])) * 2.0
        w, x = float(m[0, 2] - m[2, 0]) / s, float(m[0, 1] + m[1, 0]) / s
        y, z = 0.25 * s, float(m[1, 2] + m[2, 1]) / s
    else:
        s = math.sqrt(1.0 + float(m[2, 2] - m[0, 0] - m[1, 1])) * 2.0
        w, x = float(m[1, 0] - m[0, 1]) / s, float(m[0, 2] + m[2, 0]) / s
        y, z = float(m[1, 2] + m[2, 1]) / s, 0.25 * s
    if w < 0:
        x, y, z, w = -x, -y, -z, -w
    return x, y, z, w


def transform_difference(reference: Mat, other: Mat) -> tuple[float, float]:
    """Rotation (deg) and translation (m) of `reference^-1 @ other`: how far `other` is off."""
    delta = invert(reference) @ other
    return rotation_angle_deg(delta[:3, :3]), float(np.linalg.norm(delta[:3, 3]))


def axis_angle_about(axis: Mat, angle_rad: float) -> Mat:
    """Rotation by `angle_rad` about a (normalised here) axis."""
    unit = np.asarray(axis, dtype=np.float64)
    return exp_so3(unit / float(np.linalg.norm(unit)) * angle_rad)


def signed_angle_about_deg(rotation: Mat, axis: Mat) -> float:
    """Signed rotation angle (deg) of `rotation` about `axis` (sign of its axis along `axis`)."""
    rotvec = log_so3(rotation[:3, :3])
    angle = math.degrees(float(np.linalg.norm(rotvec)))
    return angle if float(rotvec @ axis) >= 0 else -angle
