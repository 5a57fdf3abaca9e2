"""Simulated calibration session for method B: LiDARs with non-overlapping views on a turntable.

The vehicle stops at N turntable angles (or slow-turn positions: a large pivot offset);
at each stop every LiDAR publishes `scans_per_stop` static scans, and optionally
motion-distorted scans while the vehicle turns between stops. Scans are ray-cast against
an exact scene (`syncaudit.calib.scene`) with Gaussian range noise, and written as real
`sensor_msgs/msg/PointCloud2` messages to an MCAP log (or any format `open_writer`
supports), with the *recorded* (perturbed) extrinsics on `/tf_static`. The truth -- true
and recorded extrinsics, true stop poses, the scene -- goes to `<out>.truth.json`.
"""

from __future__ import annotations

import itertools
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib import se3
from syncaudit.calib.config import CalibSceneConfig, LidarSimConfig
from syncaudit.calib.scene import Scene, beam_pattern, build_scene, simulate_scan
from syncaudit.writers.log_writer import LogFormat, LogWriter, infer_format, open_writer
from syncaudit.writers.outputs import OutputSet

__all__ = ["CalibSceneConfig", "simulate_calib_session", "truth_path"]

_NS = 1_000_000_000
_LOG_LATENCY_NS = 4_000_000
"""Delay from a scan's stamp to its log time (driver + recorder)."""

# Velodyne ROS 2 driver's XYZIRT layout: packed, so `time` sits unaligned at offset 18.
_POINT_FIELDS: tuple[tuple[str, int, int, str], ...] = (
    ("x", 0, 7, "<f4"),
    ("y", 4, 7, "<f4"),
    ("z", 8, 7, "<f4"),
    ("intensity", 12, 7, "<f4"),
    ("ring", 16, 4, "<u2"),
    ("time", 18, 7, "<f4"),
)
_POINT_STEP = 22


def truth_path(out: Path) -> Path:
    """Where the truth sidecar of a simulated log goes: `<out>.truth.json`."""
    return out.with_name(out.name + ".truth.json")


def _transform_json(transform: NDArray[np.float64]) -> dict[str, Any]:
    """A 4x4 transform as translation, quaternion, roll/pitch/yaw and the matrix."""
    qx, qy, qz, qw = se3.matrix_to_quaternion(transform[:3, :3])
    roll, pitch, yaw = se3.matrix_to_rpy(transform[:3, :3])
    return {
        "translation_m": [float(v) for v in transform[:3, 3]],
        "quaternion_xyzw": [qx, qy, qz, qw],
        "rpy_deg": [math.degrees(roll), math.degrees(pitch), math.degrees(yaw)],
        "matrix": [[float(v) for v in row] for row in transform],
    }


def _mount(lidar: LidarSimConfig) -> NDArray[np.float64]:
    """True base_from_lidar transform of a LiDAR from its mounting."""
    roll, pitch, yaw = (math.radians(v) for v in lidar.mount_rpy_deg)
    return se3.make_transform(se3.rpy_to_matrix(roll, pitch, yaw), lidar.mount_xyz_m)


def _perturb(
    true: NDArray[np.float64], rotation_deg: float, translation_cm: float, rng: np.random.Generator
) -> NDArray[np.float64]:
    """Recorded extrinsic: `true` moved by exactly `rotation_deg` and `translation_cm`."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    delta = se3.make_transform(
        se3.exp_so3(axis * math.radians(rotation_deg)), direction * translation_cm / 100.0
    )
    return true @ delta


@dataclass(frozen=True)
class _Stop:
    """One turntable stop: true vehicle pose and the time window of its static scans."""

    index: int
    yaw_rad: float
    world_from_base: NDArray[np.float64]
    start_ns: int
    end_ns: int


def _stops(config: CalibSceneConfig, rng: np.random.Generator) -> list[_Stop]:
    """Vehicle poses at each stop: rotation about the pivot plus turntable jitter."""
    pivot = np.array([*config.pivot_in_base_m, 0.0])
    stop_ns = round(config.scans_per_stop * config.scan_period_s * _NS)
    cycle_ns = stop_ns + round(config.turn_duration_s * _NS)
    t0 = round(config.start_time_s * _NS)
    stops = []
    for k in range(config.n_stops):
        yaw = math.radians(k * config.step_deg + rng.normal(0.0, config.stop_jitter_deg))
        rot = se3.rot_z(yaw)
        jitter = np.array([*rng.normal(0.0, config.stop_jitter_m, size=2), 0.0])
        pose = se3.make_transform(rot, -rot @ pivot + jitter)
        start = t0 + k * cycle_ns
        stops.append(_Stop(k, yaw, pose, start, start + stop_ns))
    return stops


def _pose_at(stops: list[_Stop], t_ns: float) -> NDArray[np.float64]:
    """Vehicle pose at time t: static within a stop, interpolated while turning."""
    for a, b in itertools.pairwise(stops):
        if t_ns < a.end_ns:
            break
        if t_ns < b.start_ns:
            s = (t_ns - a.end_ns) / (b.start_ns - a.end_ns)
            s = s * s * (3.0 - 2.0 * s)  # smooth start and stop of the turntable
            yaw = a.yaw_rad + s * (b.yaw_rad - a.yaw_rad)
            trans = (1.0 - s) * a.world_from_base[:3, 3] + s * b.world_from_base[:3, 3]
            return se3.make_transform(se3.rot_z(yaw), trans)
    for stop in reversed(stops):
        if t_ns >= stop.start_ns:
            return stop.world_from_base
    return stops[0].world_from_base


def _cloud_msg(writer: LogWriter, frame_id: str, stamp_ns: int, scan: Any, time_s: Any) -> Any:
    """A `sensor_msgs/msg/PointCloud2` (unorganised, dense) in the XYZIRT layout."""
    dtype = np.dtype(
        {
            "names": [f[0] for f in _POINT_FIELDS],
            "formats": [f[3] for f in _POINT_FIELDS],
            "offsets": [f[1] for f in _POINT_FIELDS],
            "itemsize": _POINT_STEP,
        }
    )
    n = scan.points_m.shape[0]
    packed = np.zeros(n, dtype=dtype)
    packed["x"], packed["y"], packed["z"] = scan.points_m.T
    packed["intensity"] = scan.intensity
    packed["ring"] = scan.ring
    packed["time"] = time_s
    fields = [
        writer.new_msg("sensor_msgs/msg/PointField", name=name, offset=off, datatype=dt, count=1)
        for name, off, dt, _ in _POINT_FIELDS
    ]
    return writer.new_msg(
        "sensor_msgs/msg/PointCloud2",
        header=writer.header(stamp_ns, frame_id),
        height=1,
        width=n,
        fields=fields,
        is_bigendian=False,
        point_step=_POINT_STEP,
        row_step=_POINT_STEP * n,
        data=packed.view(np.uint8).reshape(-1),
        is_dense=True,
    )


def _tf_msg(
    writer: LogWriter, stamp_ns: int, parent: str, children: dict[str, NDArray[np.float64]]
) -> Any:
    """A `tf2_msgs/msg/TFMessage` with one static transform per child frame."""
    transforms = []
    for child, transform in children.items():
        qx, qy, qz, qw = se3.matrix_to_quaternion(transform[:3, :3])
        tx, ty, tz = (float(v) for v in transform[:3, 3])
        transforms.append(
            writer.new_msg(
                "geometry_msgs/msg/TransformStamped",
                header=writer.header(stamp_ns, parent),
                child_frame_id=child,
                transform=writer.new_msg(
                    "geometry_msgs/msg/Transform",
                    translation=writer.new_msg("geometry_msgs/msg/Vector3", x=tx, y=ty, z=tz),
                    rotation=writer.new_msg("geometry_msgs/msg/Quaternion", x=qx, y=qy, z=qz, w=qw),
                ),
            )
        )
    return writer.new_msg("tf2_msgs/msg/TFMessage", transforms=transforms)


def simulate_calib_session(
    out: Path,
    config: CalibSceneConfig,
    *,
    fmt: LogFormat | None = "mcap",
    overwrite: bool = True,
    outputs: OutputSet | None = None,
) -> dict[str, Any]:
    """Write the session's log to `out` and its truth to `<out>.truth.json`; return the truth.

    `fmt` is any `open_writer` format ('mcap', 'mcap-ros1', 'db3', 'bag'; None infers it
    from the suffix). Both outputs go through `outputs` (committed by its owner) or, without
    one, through an own OutputSet committed here: all or nothing.

    Raises:
        OutputError: an output exists without `overwrite`, or cannot be written.
    """
    out = Path(out)
    fmt = infer_format(out, fmt)
    own = outputs is None
    outputs = (
        outputs
        if outputs is not None
        else OutputSet(overwrite=overwrite, overwrite_hint="pass overwrite=True to replace it")
    )
    try:
        outputs.add(truth_path(out))
        truth = _simulate(out, config, fmt, outputs)
    except BaseException:
        if own:
            outputs.discard()
        raise
    if own:
        outputs.commit()
    return truth


def _simulate(
    out: Path, config: CalibSceneConfig, fmt: LogFormat, outputs: OutputSet
) -> dict[str, Any]:
    """Write the log and the truth into `outputs`' temporaries; return the truth."""
    scene_rng = np.random.default_rng([config.seed, 0])
    pose_rng = np.random.default_rng([config.seed, 1])
    noise_rng = np.random.default_rng([config.seed, 2])
    extr_rng = np.random.default_rng([config.seed, 3])
    scene = build_scene(config.scene, scene_rng)
    stops = _stops(config, pose_rng)
    true_ext = {lidar.name: _mount(lidar) for lidar in config.lidars}
    recorded_ext = {
        lidar.name: _perturb(
            true_ext[lidar.name],
            lidar.recorded_rotation_error_deg,
            lidar.recorded_translation_error_cm,
            extr_rng,
        )
        for lidar in config.lidars
    }
    period_ns = round(config.scan_period_s * _NS)
    scans: list[dict[str, Any]] = []
    with open_writer(out, fmt, overwrite=outputs.overwrite, outputs=outputs) as writer:
        writer.add_topic(config.tf_topic, "tf2_msgs/msg/TFMessage", latched=True)
        for lidar in config.lidars:
            writer.add_topic(lidar.topic_name, "sensor_msgs/msg/PointCloud2")
        tf_stamp = stops[0].start_ns - _NS
        writer.write_msg(
            config.tf_topic,
            tf_stamp,
            _tf_msg(
                writer,
                tf_stamp,
                config.base_frame,
                {lidar.frame: recorded_ext[lidar.name] for lidar in config.lidars},
            ),
        )
        events = _scan_events(config, stops, period_ns)
        patterns = {lidar.name: beam_pattern(lidar) for lidar in config.lidars}
        for stamp_ns, lidar_index, stop_index in events:
            lidar = config.lidars[lidar_index]
            pattern = patterns[lidar.name]
            sweep_s = config.scan_period_s * lidar.horizontal_fov_deg / 360.0
            col_time_s = (np.arange(pattern.n_columns) + 0.5) / pattern.n_columns * sweep_s
            if stop_index is not None:
                pose = stops[stop_index].world_from_base @ true_ext[lidar.name]
            else:
                pose = np.stack(
                    [_pose_at(stops, stamp_ns + t * _NS) @ true_ext[lidar.name] for t in col_time_s]
                )
            scan = simulate_scan(scene, lidar, pattern, pose, noise_rng)
            msg = _cloud_msg(writer, lidar.frame, stamp_ns, scan, col_time_s[scan.column])
            writer.write_msg(lidar.topic_name, stamp_ns + _LOG_LATENCY_NS, msg)
            scans.append(
                {
                    "topic": lidar.topic_name,
                    "stamp_ns": stamp_ns,
                    "stop": stop_index,
                    "static": stop_index is not None,
                    "points": int(scan.points_m.shape[0]),
                }
            )
    truth = _truth(config, scene, stops, true_ext, recorded_ext, scans, out)
    outputs.write_text(truth_path(out), json.dumps(truth, indent=2) + "\n")
    return truth


def _scan_events(
    config: CalibSceneConfig, stops: list[_Stop], period_ns: int
) -> list[tuple[int, int, int | None]]:
    """(stamp, LiDAR index, stop index or None while turning), in time order.

    LiDARs are not phase-locked: each starts its scans a fraction of a period later.
    """
    events: list[tuple[int, int, int | None]] = []
    n = len(config.lidars)
    for i in range(n):
        phase = round(i * period_ns / (n + 1))
        for stop in stops:
            for j in range(config.scans_per_stop):
                events.append((stop.start_ns + j * period_ns + phase, i, stop.index))
        for a, b in itertools.pairwise(stops):
            gap = b.start_ns - a.end_ns
            for m in range(config.turning_scans):
                t = a.end_ns + round((m + 0.5) / config.turning_scans * gap) - period_ns // 2
                events.append((t + phase, i, None))
    events.sort()
    return events


def _truth(
    config: CalibSceneConfig,
    scene: Scene,
    stops: list[_Stop],
    true_ext: dict[str, NDArray[np.float64]],
    recorded_ext: dict[str, NDArray[np.float64]],
    scans: list[dict[str, Any]],
    out: Path,
) -> dict[str, Any]:
    """The sidecar: everything the calibration should recover, and what it was given."""
    ref = config.lidars[0]
    lidars = []
    for lidar in config.lidars:
        true_rel = se3.invert(true_ext[ref.name]) @ true_ext[lidar.name]
        rec_rel = se3.invert(recorded_ext[ref.name]) @ recorded_ext[lidar.name]
        rot_deg, trans_m = se3.transform_difference(true_rel, rec_rel)
        lidars.append(
            {
                "name": lidar.name,
                "topic": lidar.topic_name,
                "frame_id": lidar.frame,
                "beams": lidar.beams,
                "range_noise_m": lidar.range_noise_m,
                "true_base_from_lidar": _transform_json(true_ext[lidar.name]),
                "recorded_base_from_lidar": _transform_json(recorded_ext[lidar.name]),
                f"true_{ref.name}_from_lidar": _transform_json(true_rel),
                f"recorded_{ref.name}_from_lidar": _transform_json(rec_rel),
                "recorded_error": {
                    "rotation_deg": lidar.recorded_rotation_error_deg,
                    "translation_cm": lidar.recorded_translation_error_cm,
                    "relative_rotation_deg": rot_deg,
                    "relative_translation_cm": trans_m * 100.0,
                },
            }
        )
    return {
        "kind": "syncaudit.calib_session.truth",
        "log": out.name,
        "base_frame": config.base_frame,
        "reference_lidar": ref.name,
        "lidars": lidars,
        "stops": [
            {
                "index": s.index,
                "start_ns": s.start_ns,
                "end_ns": s.end_ns,
                "yaw_deg": math.degrees(s.yaw_rad),
                "world_from_base": _transform_json(s.world_from_base),
            }
            for s in stops
        ],
        "scans": scans,
        "scene": scene.to_json_dict(),
        "config": config.model_dump(mode="json"),
    }
