"""Reading a log's inputs: LiDAR topics, scans downsampled on arrival, recorded extrinsics."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from syncaudit.calib import extrinsics as extr
from syncaudit.calib import io
from syncaudit.calib.alignment.deskew import sweep_times
from syncaudit.calib.alignment.registration import backend
from syncaudit.calib.settings import CalibConfig
from syncaudit.calib.state import SampledScan
from syncaudit.errors import NoDataError

_MIN_POINTS = 100
"""Scans with fewer points after downsampling are skipped (blinded or empty sensor)."""


def choose_topics(path: Path, config: CalibConfig) -> list[str]:
    """The LiDAR topics to calibrate (configured, else all PointCloud2 topics), reference first."""
    available = io.pointcloud_topics(path)
    if config.lidar_topics is not None:
        missing = [t for t in config.lidar_topics if t not in available]
        if missing:
            raise NoDataError(f"{path}: no PointCloud2 topic {', '.join(missing)}")
        topics = list(config.lidar_topics)
    else:
        topics = sorted(available)
    if len(topics) < 2:
        found = ", ".join(topics) or "none"
        raise NoDataError(
            f"{path}: calibration needs PointCloud2 from two or more LiDARs (found {found})"
        )
    if config.reference_topic is not None:
        if config.reference_topic not in topics:
            raise NoDataError(
                f"{path}: reference topic {config.reference_topic} is not a LiDAR topic"
            )
        topics.remove(config.reference_topic)
        topics.insert(0, config.reference_topic)
    return topics


def read_scans(
    path: Path, topics: list[str], config: CalibConfig, notes: list[str]
) -> dict[str, tuple[str, list[SampledScan]]]:
    """Scans per topic, downsampled on arrival (only voxel centroids are ever used), each
    with its per-azimuth firing times (`deskew.sweep_times`: 2.9 kB a scan) when the cloud
    has a time field."""
    sg = backend()
    reg = config.registration
    frames: dict[str, str] = {}
    scans: dict[str, list[SampledScan]] = {t: [] for t in topics}
    skipped = 0
    for scan in io.iter_scans(path, topics):
        frames.setdefault(scan.topic, scan.frame_id)
        if scan.frame_id != frames[scan.topic]:
            raise NoDataError(
                f"{path}: {scan.topic} changes frame id ({frames[scan.topic]} -> {scan.frame_id})"
            )
        cloud = sg.voxelgrid_sampling(
            sg.PointCloud(np.ascontiguousarray(scan.points_m, dtype=np.float64)),
            min(reg.voxel_m, config.map_to_map.voxel_m),
            num_threads=1,
        )
        points = np.asarray(cloud.points())[:, :3].astype(np.float32)
        if points.shape[0] < _MIN_POINTS:
            skipped += 1
            continue
        sweep = None if scan.times_ns is None else sweep_times(scan.points_m, scan.times_ns)
        scans[scan.topic].append(SampledScan(scan.stamp_ns, points, sweep))
    if skipped:
        notes.append(f"{skipped} scan(s) with fewer than {_MIN_POINTS} points skipped")
    for topic in topics:
        if not scans[topic]:
            raise NoDataError(f"{path}: no usable PointCloud2 scans on {topic}")
        scans[topic].sort(key=lambda s: s.stamp_ns)
    return {t: (frames[t], scans[t]) for t in topics}


def recorded_extrinsics(
    path: Path, config: CalibConfig, frames: list[str]
) -> extr.RecordedExtrinsics:
    """The recorded extrinsics to validate: the configured file, else the log's /tf_static."""
    if config.extrinsics_file is not None:
        return extr.from_file(config.extrinsics_file, frames)
    edges = io.read_static_transforms(path, config.tf_topic)
    if not edges:
        raise NoDataError(
            f"{path}: no recorded extrinsics ({config.tf_topic} missing or empty); "
            "pass an extrinsics file"
        )
    return extr.from_static_transforms(edges, frames, f"{path.name}:{config.tf_topic}")
