"""`calibrate_log`: method B end to end on a turntable, slow-turn or driving session.

1. read the LiDARs' PointCloud2 scans (organised or not), the recorded extrinsics (any
   depth of /tf_static chain) and, when the log has it, the vehicle's odometry;
2. find still stops from scan-to-scan change (nearest-neighbour residuals, no
   registration, so low and sparse LiDARs work); scans taken while moving wait for step
   8 (each keeps its per-azimuth firing times). Refuse a degenerate scene (a direction no stop constrains: corridor,
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
7. validate against the recorded extrinsic: rotation and translation difference, pass/fail;
8. the joint estimate (`joint_estimate`): every LiDAR's stop alignments, the odometry and
   the ground planes in one graph with the extrinsics as unknowns (a stop one LiDAR saw
   still places the vehicle), cross-LiDAR stop pairs, then the scans taken while moving
   (`moving_scans`: one inside another LiDAR's still run shares that stop's pose; the
   others are deskewed with the odometry's or the neighbouring stops' motion and become
   poses of their own, each registered to the same LiDAR's stops before and after and
   kept where as sharp as a stop pair -- only when `moving_scans.use` asks: off by
   default, as they did not improve the matrix), map to map on its poses where a
   direction is still free; per LiDAR, chosen over steps 5-6 (the baseline, also
   reported) unless it leaves a direction free (which it then names; with the two maps'
   alignment in the graph, the baseline's only bridge, neither is chosen); both
   estimates' map costs on their own poses are reported (`map_consistency`).

Both maps are anchored at the *same* vehicle stop, so the vehicle's unknown motion between
stops (common to all LiDARs) cancels: the turntable angle is never needed, only
estimated, to choose stops and seed registrations. The recorded extrinsics seed the
coarse turn chain and the map-to-map GICP; the result does not otherwise depend on them.

Each stage is a package of its own, and this module only calls them in order:
`selection` (`loading`: step 1; `stops`, `stop_choice`, `degeneracy`: 2), `alignment`
(`turnchain`: 3; `registration`, `pairs`, `crosscheck`, `consensus`: 4; `crosspairs`,
`deskew`, `moving_scans`: 8),
`graph` (`links`, `stopgraph`, `posegraph`, `lidar_summary`: 5; `jointgraph`,
`vehicle_up`: 8), `refinement` (`maptomap`: 6-7; `joint_estimate`: 8) and `validation`
(`map_consistency`: the choice in 8; `outcome`, `top_view_points`: the result and its
reasons). They share one `state.LidarState` per LiDAR; `se3`, `io`, `extrinsics`,
`settings` and `result` serve every stage.
"""

from __future__ import annotations

from functools import partial
from pathlib import Path

import numpy as np

from syncaudit.calib import io
from syncaudit.calib.alignment.crosscheck import cross_check
from syncaudit.calib.alignment.moving_scans import moving_links
from syncaudit.calib.alignment.pairs import align_pairs
from syncaudit.calib.alignment.registration import backend
from syncaudit.calib.alignment.turnchain import angular_chain
from syncaudit.calib.graph import posegraph
from syncaudit.calib.graph.stopgraph import graph_lidars
from syncaudit.calib.refinement.joint_estimate import joint_extrinsics
from syncaudit.calib.refinement.maptomap import extrinsic, map_at
from syncaudit.calib.result import CalibrationResult
from syncaudit.calib.selection.degeneracy import degenerate_scene
from syncaudit.calib.selection.loading import (
    choose_topics,
    read_scans,
    recorded_extrinsics,
)
from syncaudit.calib.selection.stops import find_stops, provisional_reference
from syncaudit.calib.settings import CalibConfig
from syncaudit.calib.state import LidarState
from syncaudit.calib.validation.outcome import (
    Timer,
    library_versions,
    lidar_out,
    limits_out,
    reference_mount,
    refusal_result,
    stops_out,
    top_views,
)


def calibrate_log(path: Path, config: CalibConfig) -> CalibrationResult:
    """Calibrate the extrinsics between the log's LiDARs and validate the recorded ones."""
    path = Path(path)
    backend()
    posegraph.backend()
    timer = Timer()
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
        return refusal_result(
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
    baseline = extrinsics
    with timer.stage("joint"):
        moving = partial(moving_links, lidars, stops, recorded, odometry, config, notes)
        joint, joint_extrinsics_out = joint_extrinsics(
            lidars, reference, recorded, baseline, odometry, config, moving
        )
    extrinsics = joint_extrinsics_out
    if joint.reason and any(sel.method == "baseline" for sel in joint.selection):
        notes.append(f"joint graph not used: {joint.reason}")
    with timer.stage("top_views"):
        tops = top_views(lidars, anchors, extrinsics, recorded)
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
    if failures and joint.reason:
        failures.insert(0, joint.reason)
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
        limits=limits_out(config),
        stops=stops_out(stops),
        lidars=[lidar_out(lidar, stops, top) for lidar, top in zip(lidars, tops, strict=True)],
        extrinsics=extrinsics,
        baseline=baseline,
        joint=joint,
        notes=notes,
        timings_s=dict(timer.seconds),
        libraries=library_versions(),
        reference_mount=reference_mount(recorded, lidars[0].frame_id),
    )
