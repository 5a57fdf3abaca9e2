"""Rigid transforms (round trips), PointCloud2 decoding and the turn checks."""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from syncaudit.calib import se3
from syncaudit.calib.io import decode_xyz, pointcloud2_dtype
from syncaudit.errors import LogReadError, NoDataError


def test_rotation_round_trips() -> None:
    rng = np.random.default_rng(3)
    for _ in range(50):
        rotvec = rng.normal(size=3)
        rotvec *= rng.uniform(0.0, math.pi - 1e-3) / np.linalg.norm(rotvec)
        rot = se3.exp_so3(rotvec)
        assert np.allclose(rot @ rot.T, np.eye(3), atol=1e-12)
        assert np.allclose(se3.log_so3(rot), rotvec, atol=1e-9)
        assert np.allclose(
            se3.quaternion_to_matrix(*se3.matrix_to_quaternion(rot)), rot, atol=1e-12
        )
        assert np.allclose(se3.rpy_to_matrix(*se3.matrix_to_rpy(rot)), rot, atol=1e-12)
    near_pi = se3.exp_so3(np.array([0.0, 0.0, math.pi - 1e-6]))
    assert se3.rotation_angle_deg(near_pi) == pytest.approx(180.0, abs=1e-3)


def test_transform_difference_is_exact() -> None:
    base = se3.make_transform(se3.rpy_to_matrix(0.1, -0.2, 2.0), (1.0, 2.0, 3.0))
    delta = se3.make_transform(
        se3.axis_angle_about(np.array([1.0, 1.0, 0.0]), math.radians(1.0)), (0.03, 0.0, 0.04)
    )
    rot_deg, trans_m = se3.transform_difference(base, base @ delta)
    assert rot_deg == pytest.approx(1.0, abs=1e-9)
    assert trans_m == pytest.approx(0.05, abs=1e-12)
    assert np.allclose(se3.invert(base) @ base, np.eye(4), atol=1e-12)


def _cloud(
    fields: list[tuple[str, int, int, int]],
    packed: bytes,
    width: int,
    height: int,
    point_step: int,
    row_step: int,
    bigendian: bool = False,
) -> Any:
    return SimpleNamespace(
        fields=[SimpleNamespace(name=n, offset=o, datatype=d, count=c) for n, o, d, c in fields],
        width=width,
        height=height,
        point_step=point_step,
        row_step=row_step,
        is_bigendian=bigendian,
        data=np.frombuffer(packed, dtype=np.uint8),
    )


def test_decode_packed_padded_and_big_endian_clouds() -> None:
    xyz = np.array([[1.0, 2.0, 3.0], [np.nan, 0.0, 0.0], [0.0, 0.0, 0.0], [4.0, 5.0, 6.0]])
    fields = [("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("ring", 12, 4, 1), ("rgb", 14, 2, 3)]
    for order in ("<", ">"):
        dtype = pointcloud2_dtype(
            [SimpleNamespace(name=n, offset=o, datatype=d, count=c) for n, o, d, c in fields],
            20,
            order == ">",
        )
        rows = np.zeros(4, dtype=dtype)
        rows["x"], rows["y"], rows["z"] = xyz.T
        rows["ring"] = [1, 2, 3, 4]
        # Two rows of two points, each row padded with 8 bytes.
        raw = rows.tobytes()
        padded = raw[:40] + b"\xff" * 8 + raw[40:] + b"\xff" * 8
        msg = _cloud(fields, padded, 2, 2, 20, 48, bigendian=order == ">")
        out = decode_xyz(msg, "/t")
        assert out.dtype == np.float32
        assert np.array_equal(out, np.array([[1, 2, 3], [4, 5, 6]], dtype=np.float32))
        # Unpadded, the points are read straight from the buffer.
        assert decode_xyz(_cloud(fields, raw, 4, 1, 20, 80, order == ">"), "/t").shape == (2, 3)


def test_decode_rejects_broken_clouds() -> None:
    fields = [("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1)]
    with pytest.raises(LogReadError, match="overruns"):
        decode_xyz(_cloud([*fields, ("w", 10, 7, 1)], bytes(12), 1, 1, 12, 12), "/t")
    with pytest.raises(LogReadError, match="bytes"):
        decode_xyz(_cloud(fields, bytes(12), 2, 1, 12, 24), "/t")
    with pytest.raises(LogReadError, match="datatype"):
        decode_xyz(
            _cloud([("x", 0, 9, 1), ("y", 4, 7, 1), ("z", 8, 7, 1)], bytes(12), 1, 1, 12, 12), "/t"
        )
    with pytest.raises(NoDataError, match="x/y/z"):
        decode_xyz(_cloud([("a", 0, 7, 1)], bytes(4), 1, 1, 4, 4), "/t")
    assert decode_xyz(_cloud(fields, b"", 0, 1, 12, 0), "/t").shape == (0, 3)
