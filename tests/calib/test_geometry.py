"""Rigid transforms (round trips), PointCloud2 decoding and the turn checks."""

from __future__ import annotations

import math
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from syncaudit.calib import se3
from syncaudit.calib.io import decode_xyz, pointcloud2_dtype
from syncaudit.calib.registration import prepare
from syncaudit.calib.settings import CalibConfig
from syncaudit.calib.turnchain import verify_turn
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


def test_a_coarse_turn_that_tilts_or_rises_is_not_a_drive_on_level_ground() -> None:
    """The turn chain's second criterion refuses a motion no vehicle on level ground makes
    (a yaw search that converged upside down: tilt 179 deg, as measured on a
    diagonal-mount drive) before looking at the scans; a level turn is judged on them."""
    rng = np.random.default_rng(5)
    walls = [
        np.column_stack([rng.uniform(-8, 8, 400), np.full(400, y), rng.uniform(0, 3, 400)])
        for y in (-6.0, 6.0)
    ] + [
        np.column_stack([np.full(400, x), rng.uniform(-6, 6, 400), rng.uniform(0, 3, 400)])
        for x in (-8.0, 8.0)
    ]
    cloud = prepare(np.concatenate(walls), 0.5, 20, 1)
    config = CalibConfig()
    flipped = se3.make_transform(se3.rpy_to_matrix(math.pi, 0.0, 0.4), (0.1, 0.6, 3.84))
    why = verify_turn((cloud, cloud), (cloud, cloud), flipped, config)
    assert why == "not a motion on level ground (the base tilts 180.0 deg)"
    tilted = se3.make_transform(se3.rpy_to_matrix(0.0, math.radians(12.0), 0.5), (0.3, 0.1, 0.0))
    assert verify_turn((cloud, cloud), (cloud, cloud), tilted, config) == (
        "not a motion on level ground (the base tilts 12.0 deg)"
    )
    assert verify_turn((cloud, cloud), (cloud, cloud), np.eye(4), config) is None
    free = config.model_copy(
        update={"pose_graph": config.pose_graph.model_copy(update={"motion": "free"})}
    )
    assert not (verify_turn((cloud, cloud), (cloud, cloud), flipped, free) or "").startswith(
        "not a motion on level ground"
    )


def test_turn_axis_leaves_out_an_alignment_that_tilts_out_of_the_plane() -> None:
    """A planar vehicle's turns are rotations about one axis: an alignment tilted 0.9 deg
    out of that plane (as an 11 %-overlap one on a bumper drive was) must not pull the
    axis, while small per-alignment noise (0.03 deg) is averaged, not refused."""
    from syncaudit.calib import posegraph

    rng = np.random.default_rng(3)
    tilt = se3.rpy_to_matrix(math.radians(0.4), math.radians(1.7), math.radians(0.9))
    axis = tilt.T @ np.array([0.0, 0.0, 1.0])
    yaws_deg = [0.0, 38.0, 71.0, 104.0, 140.0, 175.0, 212.0, 249.0]

    def edge(a: int, b: int, extra_deg: float) -> posegraph.Edge:
        turn = math.radians(yaws_deg[b] - yaws_deg[a])
        noise = rng.normal(size=3)
        noise *= math.radians(0.03) / float(np.linalg.norm(noise))
        across = np.cross(axis, [1.0, 0.0, 0.0])
        rot = (
            se3.axis_angle_about(across, math.radians(extra_deg))
            if extra_deg
            else se3.axis_angle_about(noise, float(np.linalg.norm(noise)))
        ) @ se3.axis_angle_about(axis, turn)
        return posegraph.Edge(a, b, se3.make_transform(rot, (0.2, 0.1, 0.0)), np.eye(6), 1.0)

    good = [edge(a, a + 1, 0.0) for a in range(7)] + [edge(a, a + 2, 0.0) for a in range(0, 6, 2)]
    bad = edge(3, 5, 0.9)
    hint = axis + np.array([0.05, 0.0, 0.0])

    def error_deg(found: Any) -> float:
        return math.degrees(math.acos(min(1.0, float(found @ axis))))

    assert posegraph.tilting_edges(good, axis, hint) == []
    assert error_deg(posegraph.turn_axis(good, hint)) < 0.01
    assert posegraph.tilting_edges([*good, bad], axis, hint) == [(3, 5)]
    assert error_deg(posegraph.turn_axis([*good, bad], hint)) < 0.01
