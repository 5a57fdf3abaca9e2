"""The calibration's result from the working state: per-LiDAR outputs, top views, refusals."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path

import numpy as np

from syncaudit.calib import extrinsics as extr
from syncaudit.calib.graph.stopgraph import poses_at
from syncaudit.calib.result import (
    CalibrationResult,
    DegeneracyOut,
    ExtrinsicOut,
    LidarOut,
    Limits,
    StopUse,
    TopViewOut,
    TransformOut,
    VehicleStopOut,
)
from syncaudit.calib.selection import stop_choice
from syncaudit.calib.settings import CalibConfig
from syncaudit.calib.state import LidarState
from syncaudit.calib.validation import top_view_points


class Timer:
    """Wall-clock seconds per named stage (the result's `timings_s`)."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """Time the block as stage `name` (added up when a stage runs more than once)."""
        start = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - start


def library_versions() -> dict[str, str]:
    """Installed versions of the registration libraries, so a result says what made it."""
    out = {}
    for dist in ("small_gicp", "gtsam"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = "unknown"
    return out


def reference_mount(recorded: extr.RecordedExtrinsics, frame_id: str) -> TransformOut | None:
    """The reference LiDAR's recorded base_from_frame (the report places mounts with it)."""
    transform = recorded.base_from_frame.get(frame_id)
    return None if transform is None else TransformOut.of(transform)


def limits_out(config: CalibConfig) -> Limits:
    """The validation limits as the result reports them."""
    return Limits(
        max_rotation_deg=config.validation.max_rotation_deg,
        max_translation_cm=config.validation.max_translation_cm,
    )


def stops_out(stops: list[stop_choice.VehicleStop]) -> list[VehicleStopOut]:
    """The vehicle's stops as the result reports them."""
    return [
        VehicleStopOut(index=s.index, start_ns=s.start_ns, end_ns=s.end_ns, topics=sorted(s.runs))
        for s in stops
    ]


def lidar_out(
    lidar: LidarState, stops: list[stop_choice.VehicleStop], top: TopViewOut | None = None
) -> LidarOut:
    """One LiDAR as the result reports it: each stop used or why not, turn axis, pairs, graph."""
    uses = []
    for stop in stops:
        run = stop.runs.get(lidar.topic)
        if run is None:
            continue
        used = stop.index in lidar.used
        reason = None if used else lidar.dropped.get(stop.index, "not aligned")
        uses.append(
            StopUse(
                stop=stop.index,
                stamp_ns=lidar.scans[run.representative].stamp_ns,
                static_scans=len(run.indices),
                angle_deg=lidar.angles.get(stop.index),
                used=used,
                reason=reason,
            )
        )
    axis, tilt = None, None
    if lidar.turn_axis is not None:
        axis = (float(lidar.turn_axis[0]), float(lidar.turn_axis[1]), float(lidar.turn_axis[2]))
        cos = float(np.clip(lidar.turn_axis @ lidar.up / np.linalg.norm(lidar.up), -1.0, 1.0))
        tilt = math.degrees(math.acos(cos))
    return LidarOut(
        topic=lidar.topic,
        frame_id=lidar.frame_id,
        scans=len(lidar.scans),
        horizontal_fov_deg=lidar.hfov_deg,
        turn_axis=axis,
        turn_axis_vs_recorded_deg=tilt,
        stops=uses,
        pairs=lidar.pairs,
        pose_graph=lidar.graph,
        map_points=lidar.map_points,
        aligned=bool(lidar.graphs),
        reason=lidar.reason,
        top_view=top,
        moving_scans=lidar.moving,
    )


def top_views(
    lidars: list[LidarState],
    anchors: list[int],
    extrinsics: list[ExtrinsicOut],
    recorded: extr.RecordedExtrinsics,
) -> list[TopViewOut | None]:
    """Each LiDAR's placed stops from above, in the base frame at the first anchor its
    pose graph holds; a non-reference LiDAR is mounted through its calibrated extrinsic
    when there is one, else the recorded one (the frame text says which)."""
    ref = lidars[0]
    base_from_ref = recorded.base_from_frame[ref.frame_id]
    calibrated = {e.topic: np.array(e.result.matrix) for e in extrinsics if e.result is not None}
    out: list[TopViewOut | None] = []
    for lidar in lidars:
        found = next(((a, p) for a in anchors if (p := poses_at(lidar, a)) is not None), None)
        if found is None:
            out.append(None)
            continue
        anchor, poses = found
        if lidar is ref:
            mount, via = base_from_ref, "the recorded extrinsic"
        elif lidar.topic in calibrated:
            mount, via = base_from_ref @ calibrated[lidar.topic], "the calibrated extrinsic"
        else:
            mount, via = recorded.base_from_frame[lidar.frame_id], "the recorded extrinsic"
        scans = {k: lidar.scans[lidar.stop_scan[k]].points_m for k in poses}
        frame = f"{recorded.base_frame} at stop {anchor}, {lidar.frame_id} placed by {via}"
        out.append(top_view_points.top_view(scans, poses, mount, frame))
    return out


def refusal_result(
    path: Path,
    lidars: list[LidarState],
    recorded: extr.RecordedExtrinsics,
    stops: list[stop_choice.VehicleStop],
    why: str,
    notes: list[str],
    timer: Timer,
    config: CalibConfig,
    *,
    degeneracy: DegeneracyOut | None = None,
) -> CalibrationResult:
    """A not-calibratable result for a log that has scans but cannot be calibrated
    (`degeneracy`: the scene's free direction when that is why)."""
    for lidar in lidars:
        lidar.reason = why
    ref = lidars[0]
    extrinsics = []
    for other in lidars[1:]:
        extrinsics.append(
            ExtrinsicOut(
                topic=other.topic,
                frame_id=other.frame_id,
                reference_topic=ref.topic,
                reference_frame_id=ref.frame_id,
                recorded=TransformOut.of(recorded.relative(ref.frame_id, other.frame_id)),
                calibrated=False,
                reason=why,
                result=None,
                rotation_diff_deg=None,
                translation_diff_cm=None,
                diff_rpy_deg=None,
                diff_xyz_cm=None,
                passed=False,
                map_to_map=None,
                stop_angle_disagreement_deg=None,
                hand_eye_rotation_residual_deg=None,
            )
        )
    timer.seconds["total"] = sum(timer.seconds.values())
    return CalibrationResult(
        log=str(path),
        calibratable=False,
        reason="not calibratable: " + why,
        passed=False,
        reference_topic=ref.topic,
        reference_frame_id=ref.frame_id,
        base_frame=recorded.base_frame,
        extrinsics_source=recorded.source,
        reference_stop=None,
        anchor_stops=[],
        limits=limits_out(config),
        degeneracy=degeneracy,
        stops=stops_out(stops),
        lidars=[lidar_out(lidar, stops) for lidar in lidars],
        extrinsics=extrinsics,
        notes=notes,
        timings_s=dict(timer.seconds),
        libraries=library_versions(),
        reference_mount=reference_mount(recorded, ref.frame_id),
    )
