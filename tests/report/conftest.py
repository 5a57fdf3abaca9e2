"""Fixtures of the report tests: a real audit of a sample log, calibration results."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from syncaudit.audit.run import AuditResult, audit_log
from syncaudit.calib.result import CalibrationResult, StopPointsOut, TopViewOut, TransformOut
from syncaudit.rig import load_rig

REPO = Path(__file__).resolve().parents[2]
THREE_CAMERAS = REPO / "sample_logs" / "vlp16_three_cameras.mcap"
DATA = Path(__file__).resolve().parent / "data"
HOSTILE = '<script>alert("x")</script>&amp;'
"""Text a log could carry (a camera name, a topic, a frame id) that must show as text."""


@functools.cache
def _audit() -> AuditResult:
    return audit_log(THREE_CAMERAS, load_rig(Path(f"{THREE_CAMERAS}.rig.yaml")), jobs=1)


@pytest.fixture()
def audit() -> AuditResult:
    """The audit of the three-camera sample (real decoding; computed once per session)."""
    return _audit()


@pytest.fixture()
def hostile_audit() -> AuditResult:
    """The same audit with a camera name, the LiDAR topic and a warning holding markup."""
    base = _audit()
    first = dataclasses.replace(base.cameras[0])
    first.sync = dataclasses.replace(first.sync, camera=f"cam{HOSTILE}")
    return dataclasses.replace(
        base,
        path=f"/logs/{HOSTILE}.mcap",
        lidar=dataclasses.replace(base.lidar, topic=f"/lidar{HOSTILE}"),
        cameras=[first, *base.cameras[1:]],
        warnings=[*base.warnings, f"frame id {HOSTILE} unknown"],
    )


def _calibration(name: str) -> CalibrationResult:
    return CalibrationResult.model_validate_json((DATA / f"{name}.json").read_bytes())


@pytest.fixture()
def calibration() -> Callable[[str], CalibrationResult]:
    """Load a saved calibration result by name (tests/report/data, see its README)."""
    return _calibration


@pytest.fixture()
def hostile() -> str:
    """Markup that a log's text could carry."""
    return HOSTILE


def room_points_m(spacing_m: float = 0.1) -> np.ndarray:
    """Walls of a 20 m x 14 m hall and a 2 m box inside it, from above (x, y; metres)."""
    edges = [((-8, -7), (12, -7)), ((12, -7), (12, 7)), ((12, 7), (-8, 7)), ((-8, 7), (-8, -7))]
    edges += [((4, 2), (6, 2)), ((6, 2), (6, 4)), ((6, 4), (4, 4)), ((4, 4), (4, 2))]
    out = []
    for (x0, y0), (x1, y1) in edges:
        n = round(float(np.hypot(x1 - x0, y1 - y0)) / spacing_m)
        f = np.arange(n) / n
        out.append(np.stack([x0 + (x1 - x0) * f, y0 + (y1 - y0) * f], axis=1))
    return np.concatenate(out)


def with_top_views(
    result: CalibrationResult,
    *,
    spacing_m: float = 0.1,
    sector_deg: float = 140.0,
    frames: dict[str, str] | None = None,
    base_from_reference: np.ndarray | None = None,
) -> CalibrationResult:
    """`result` with a top view per LiDAR, as the pipeline would place its stops.

    The truth: the hall of `room_points_m` in the reference LiDAR's frame. Each LiDAR's
    map is in its own frame at stop 0 (the reference's recorded pose of it), or with
    `base_from_reference` in the base frame as the pipeline draws them (and the result
    then keeps that mount as `reference_mount`); stop k holds the walls the LiDAR sees
    within `sector_deg` around the turntable angle of stop k.
    """
    room = room_points_m(spacing_m)
    lidars = []
    for lidar in result.lidars:
        if lidar.frame_id == result.reference_frame_id:
            pose = np.eye(4)
        else:
            ext = next(e for e in result.extrinsics if e.frame_id == lidar.frame_id)
            pose = np.linalg.inv(np.asarray(ext.recorded.matrix))
        own = (pose[:2, :2] @ room.T).T + pose[:2, 3]
        bearing = np.degrees(np.arctan2(own[:, 1], own[:, 0]))
        base = base_from_reference
        xy = own if base is None else (base[:2, :2] @ room.T).T + base[:2, 3]
        stops = []
        for use in lidar.stops:
            if not use.used or use.angle_deg is None:
                continue
            off = (bearing - use.angle_deg + 180.0) % 360.0 - 180.0
            keep = np.abs(off) <= sector_deg / 2
            stops.append(
                StopPointsOut(stop=use.stop, x_m=xy[keep, 0].tolist(), y_m=xy[keep, 1].tolist())
            )
        default = (
            f"{lidar.frame_id} at stop 0"
            if base is None
            else f"{result.base_frame} at stop 0, {lidar.frame_id} placed by the recorded extrinsic"
        )
        frame = (frames or {}).get(lidar.frame_id, default)
        view = TopViewOut(frame=frame, cell_m=spacing_m, stops=stops)
        lidars.append(lidar.model_copy(update={"top_view": view}))
    update: dict[str, object] = {"lidars": lidars}
    if base_from_reference is not None:
        update["reference_mount"] = TransformOut.of(base_from_reference)
    return result.model_copy(update=update)


@pytest.fixture()
def top_views() -> Callable[..., CalibrationResult]:
    """`with_top_views`: a calibration result with a known top view per LiDAR."""
    return with_top_views
