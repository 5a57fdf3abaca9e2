"""Stop detection: still runs of each LiDAR's scans, merged into the vehicle's stops."""

from __future__ import annotations

import numpy as np

from syncaudit.calib.alignment.registration import Cloud, backend
from syncaudit.calib.selection import stop_choice
from syncaudit.calib.settings import CalibConfig
from syncaudit.calib.state import LidarState
from syncaudit.errors import NoDataError


def _scan_changes(lidar: LidarState, config: CalibConfig) -> list[tuple[float, float] | None]:
    """Scan-to-scan change of each scan against the one before (None for the first)."""
    sg = backend()
    threads = config.registration.num_threads
    out: list[tuple[float, float] | None] = [None]
    previous: Cloud | None = None
    for scan in lidar.scans:
        raw = np.ascontiguousarray(scan.points_m, dtype=np.float64)
        cloud = Cloud(raw, np.zeros_like(raw), None, sg.KdTree(raw, num_threads=threads), 0.0)
        if previous is not None:
            out.append(stop_choice.scan_change(previous, cloud, threads))
        previous = cloud
    return out


def find_stops(
    lidars: list[LidarState], config: CalibConfig, notes: list[str]
) -> list[stop_choice.VehicleStop]:
    """Still runs per LiDAR (scan-to-scan change, no registration), merged across LiDARs
    into vehicle stops."""
    sel = config.selection
    runs: list[stop_choice.Run] = []
    for lidar in lidars:
        runs += stop_choice.static_runs(
            lidar.topic,
            [s.stamp_ns for s in lidar.scans],
            _scan_changes(lidar, config),
            min_scans=sel.min_static_scans,
            max_residual_m=sel.static_residual_m,
            min_near_fraction=sel.static_near_fraction,
            max_gap_ns=round(sel.max_static_gap_s * 1e9),
        )
    if not runs:
        notes.append(
            "no two consecutive scans of any LiDAR are alike (one scan per stop): every scan "
            "is treated as a stop"
        )
        for lidar in lidars:
            runs += [
                stop_choice.Run(lidar.topic, (i,), s.stamp_ns, s.stamp_ns)
                for i, s in enumerate(lidar.scans)
            ]
    moving = sum(len(lidar.scans) for lidar in lidars) - sum(len(r.indices) for r in runs)
    if moving:
        notes.append(
            f"{moving} scan(s) taken while moving (or isolated): not used to find stops; "
            "once the stops are placed they are deskewed and registered if moving_scans.use "
            "asks (each LiDAR's moving_scans says how many there were and were used)"
        )
    tolerance_ns = round(sel.stop_match_tolerance_s * 1e9)
    stops = stop_choice.group_stops(runs, tolerance_ns)
    for stop in stops:
        for topic, run in stop.runs.items():
            lidar = next(lidar for lidar in lidars if lidar.topic == topic)
            lidar.stop_scan[stop.index] = run.representative
    return stops


def provisional_reference(
    stops: list[stop_choice.VehicleStop], lidars: list[LidarState], config: CalibConfig
) -> int:
    """The configured reference stop, else the first stop every LiDAR has a static scan of."""
    topics = {lidar.topic for lidar in lidars}
    if config.selection.reference_stop is not None:
        ref = config.selection.reference_stop
        if ref >= len(stops):
            raise NoDataError(f"reference stop {ref} does not exist (found {len(stops)} stops)")
        if set(stops[ref].runs) != topics:
            raise NoDataError(f"reference stop {ref} lacks a static scan of every LiDAR")
        return ref
    for stop in stops:
        if set(stop.runs) == topics:
            return stop.index
    raise NoDataError(
        "no stop where every LiDAR has a static scan (needed as the common reference)"
    )
