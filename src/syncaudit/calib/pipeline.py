"""`calibrate_log`: method B end to end on a turntable, slow-turn or driving session.

1. read the LiDARs' PointCloud2 scans (organised or not), the recorded extrinsics (any
   depth of /tf_static chain) and, when the log has it, the vehicle's odometry;
2. find still stops from scan-to-scan change (nearest-neighbour residuals, no
   registration, so low and sparse LiDARs work); scans taken while moving are skipped,
   not deskewed. Refuse a degenerate scene (a direction no stop constrains: corridor,
   ground plus one wall) before any registration, naming the free direction; a log
   with too few stops gets a not-calibratable result saying why, never "nothing to audit";
3. the vehicle's motion between stops (all LiDARs merged in the base frame): seeded by
   odometry when present, else a yaw search scored on the structure off the ground
   (ground plane fitted and removed), verified by a second criterion; a stop links to
   the nearest earlier stop whose motion verifies, so one weak link does not drop the rest;
4. per LiDAR, align every pair of stops whose views should overlap with GICP; accept on
   point-to-plane error and conditioning (planar directions for a planar graph), with
   overlap judged against the share the two views allow at the seed pose; reject one that
   moved far from the vehicle's coarse motion along a barely constrained direction (slid);
5. per LiDAR, a pose graph (gtsam, robust kernel, planar by default) over each group of
   stops the firm accepted alignments connect (weaker ones only close loops inside a
   group, so a lone weak link cannot carry a slide into the map), anchored at a stop
   shared with the other LiDARs: every scan lands in that LiDAR's frame at the anchor
   stop -- its local map;
6. GICP between the reference LiDAR's map and each other LiDAR's map anchored at the same
   stop, both built from the stops the two graphs share there (the whole maps only when
   no anchor's shared stops gave an accepted alignment), seeded with the recorded
   extrinsic: the result is `reference_from_lidar`, the extrinsic calibration (estimates
   from several anchors are fused by their information);
7. validate against the recorded extrinsic: rotation and translation difference, pass/fail.

Both maps are anchored at the *same* vehicle stop, so the vehicle's unknown motion between
stops (common to all LiDARs) cancels: the turntable angle is never needed, only
estimated, to choose stops and seed registrations. The recorded extrinsics seed the
coarse turn chain and the map-to-map GICP; the result does not otherwise depend on them.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from importlib import metadata
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib import extrinsics as extr
from syncaudit.calib import io, posegraph, selection, topview
from syncaudit.calib.config import CalibConfig
from syncaudit.calib.crosscheck import cross_check
from syncaudit.calib.degeneracy import degenerate_scene
from syncaudit.calib.loading import choose_topics, read_scans, recorded_extrinsics
from syncaudit.calib.maptomap import extrinsic, map_at
from syncaudit.calib.pairs import align_pairs
from syncaudit.calib.registration import backend
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
from syncaudit.calib.state import LidarState
from syncaudit.calib.stopgraph import graph_lidars, poses_at
from syncaudit.calib.stops import find_stops, provisional_reference
from syncaudit.calib.turnchain import angular_chain

F64 = NDArray[np.float64]


class _Timer:
    """Wall-clock seconds per named stage."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        start = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - start


def _library_versions() -> dict[str, str]:
    out = {}
    for dist in ("small_gicp", "gtsam"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[dist] = "unknown"
    return out


def _reference_mount(recorded: extr.RecordedExtrinsics, frame_id: str) -> TransformOut | None:
    """The reference LiDAR's recorded base_from_frame (the report places mounts with it)."""
    transform = recorded.base_from_frame.get(frame_id)
    return None if transform is None else TransformOut.of(transform)


def _limits_out(config: CalibConfig) -> Limits:
    """The validation limits as the result reports them."""
    return Limits(
        max_rotation_deg=config.validation.max_rotation_deg,
        max_translation_cm=config.validation.max_translation_cm,
    )


def _stops_out(stops: list[selection.VehicleStop]) -> list[VehicleStopOut]:
    """The vehicle's stops as the result reports them."""
    return [
        VehicleStopOut(index=s.index, start_ns=s.start_ns, end_ns=s.end_ns, topics=sorted(s.runs))
        for s in stops
    ]


def _lidar_out(
    lidar: LidarState, stops: list[selection.VehicleStop], top: TopViewOut | None = None
) -> LidarOut:
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
    )


def _top_views(
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
        out.append(topview.top_view(scans, poses, mount, frame))
    return out


def _refusal(
    path: Path,
    lidars: list[LidarState],
    recorded: extr.RecordedExtrinsics,
    stops: list[selection.VehicleStop],
    why: str,
    notes: list[str],
    timer: _Timer,
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
        limits=_limits_out(config),
        degeneracy=degeneracy,
        stops=_stops_out(stops),
        lidars=[_lidar_out(lidar, stops) for lidar in lidars],
        extrinsics=extrinsics,
        notes=notes,
        timings_s=dict(timer.seconds),
        libraries=_library_versions(),
        reference_mount=_reference_mount(recorded, ref.frame_id),
    )


def calibrate_log(path: Path, config: CalibConfig) -> CalibrationResult:
    """Calibrate the extrinsics between the log's LiDARs and validate the recorded ones."""
    path = Path(path)
    backend()
    posegraph.backend()
    timer = _Timer()
    notes: list[str] = []
    with timer.stage("read"):
        topics = choose_topics(path, config)
        read = read_scans(path, topics, config, notes)
        recorded = recorded_extrinsics(path, config, [read[t][0] for t in topics])
    lidars = []
    for topic in topics:
        frame, scans = read[topic]
        up = recorded.base_from_frame[frame][:3, :3].T @ np.array([0.0, 0.0, 1.0])
        lidars.append(LidarState(topic=topic, frame_id=frame, scans=scans, up=up))
    with timer.stage("stops"):
        stops = find_stops(lidars, config, notes)
    with timer.stage("degeneracy"):
        degenerate = degenerate_scene(lidars, recorded, config)
    refusal, degeneracy = degenerate if degenerate is not None else (None, None)
    short = [
        f"{lidar.topic} has {len(lidar.stop_scan)} stop(s) among {len(lidar.scans)} scans"
        for lidar in lidars
        if len(lidar.stop_scan) < config.selection.min_stops
    ]
    if refusal is None and short:
        refusal = (
            "; ".join(short) + f"; calibration needs at least {config.selection.min_stops} stops "
            f"(runs of {config.selection.min_static_scans}+ still scans) per LiDAR"
        )
    if refusal is not None:
        return _refusal(
            path, lidars, recorded, stops, refusal, notes, timer, config, degeneracy=degeneracy
        )
    reference = provisional_reference(stops, lidars, config)
    with timer.stage("turn_chain"):
        odometry = io.read_odometry(path, recorded.base_frame)
        reference = angular_chain(lidars, recorded, reference, config, odometry, notes)
    with timer.stage("align_pairs"):
        for lidar in lidars:
            align_pairs(lidar, reference, config)
    with timer.stage("cross_check"):
        cross_check(lidars, recorded, reference, config, notes)
    with timer.stage("pose_graphs"):
        anchors = graph_lidars(lidars, config)
        reference = anchors[0]
    with timer.stage("map_to_map"):
        extrinsics = [
            extrinsic(lidars[0], other, anchors, recorded, config) for other in lidars[1:]
        ]
        for lidar in lidars:
            local = map_at(lidar, reference, config)
            lidar.map_points = 0 if local is None else local[0].size
    with timer.stage("top_views"):
        tops = _top_views(lidars, anchors, extrinsics, recorded)
    limits = config.validation
    for ext in extrinsics:
        spread_deg, spread_cm = ext.estimate_spread_deg, ext.estimate_spread_cm
        if (
            spread_deg is not None
            and spread_cm is not None
            and (
                spread_deg > limits.max_rotation_deg / 2
                or spread_cm > limits.max_translation_cm / 2
            )
        ):
            notes.append(
                f"{ext.frame_id}: the map pairs' estimates differ from their fused result by up "
                f"to {spread_deg:.3f} deg / {spread_cm:.2f} cm (over half the limits): more stops "
                "or a richer scene would make the calibration firmer"
            )
    failures = [e.reason for e in extrinsics if not e.calibrated and e.reason]
    calibratable = not failures
    timer.seconds["total"] = sum(timer.seconds.values())
    return CalibrationResult(
        log=str(path),
        calibratable=calibratable,
        reason=None if calibratable else "not calibratable: " + "; ".join(dict.fromkeys(failures)),
        passed=calibratable and all(e.passed for e in extrinsics),
        reference_topic=lidars[0].topic,
        reference_frame_id=lidars[0].frame_id,
        base_frame=recorded.base_frame,
        extrinsics_source=recorded.source,
        reference_stop=reference,
        anchor_stops=anchors,
        limits=_limits_out(config),
        stops=_stops_out(stops),
        lidars=[_lidar_out(lidar, stops, top) for lidar, top in zip(lidars, tops, strict=True)],
        extrinsics=extrinsics,
        notes=notes,
        timings_s=dict(timer.seconds),
        libraries=_library_versions(),
        reference_mount=_reference_mount(recorded, lidars[0].frame_id),
    )
