"""Choosing scans: stationary stops, their angular positions, and which pairs to align.

A stop is a run of consecutive scans of one LiDAR that re-hit the same surfaces (nearest
neighbour residuals at the noise level, no registration needed); scans taken while the
vehicle moves are motion-distorted and left out.
Stops of different LiDARs that overlap in time are the same vehicle stop. The angle of
each stop about the turntable axis comes from a coarse registration chain, and it decides
which stops are kept (distinct positions) and which pairs should overlap.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib import se3
from syncaudit.calib.alignment.registration import Cloud

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class Run:
    """Consecutive static scans of one LiDAR (indices into its time-ordered scan list)."""

    topic: str
    indices: tuple[int, ...]
    start_ns: int
    end_ns: int

    @property
    def representative(self) -> int:
        """The middle scan of the run: furthest from the motion before and after."""
        return self.indices[len(self.indices) // 2]


def scan_change(
    previous: Cloud, current: Cloud, threads: int, *, near_m: float = 0.05
) -> tuple[float, float]:
    """How much a scan differs from the one before: (median nearest-neighbour distance of
    its points to the previous scan, fraction within `near_m`).

    No registration is involved, so a view that constrains motion poorly (a low LiDAR
    above bare ground) is judged as well as a rich one: still scans re-hit the same
    surfaces at the same places (residual at the range-noise level), moving ones do not.
    """
    _idx, sq = previous.tree.batch_nearest_neighbor_search(current.points_m, num_threads=threads)
    dist = np.sqrt(np.asarray(sq, dtype=np.float64))
    return float(np.median(dist)), float(np.mean(dist <= near_m))


def static_runs(
    topic: str,
    stamps_ns: list[int],
    changes: list[tuple[float, float] | None],
    *,
    min_scans: int,
    max_residual_m: float,
    min_near_fraction: float,
    max_gap_ns: int,
) -> list[Run]:
    """Runs of at least `min_scans` consecutive scans with no change between neighbours.

    `changes[i]` is `scan_change(scan i-1, scan i)` (None for the first). A pair is still
    when its median residual is within `max_residual_m` -- or within 1.5 times the
    quietest tenth of this LiDAR's pairs, whichever is larger (noisier sensors) -- and
    at least `min_near_fraction` of the points are near the previous scan. Neighbours
    further apart in time than `max_gap_ns` never count as still.
    """
    medians = [c[0] for c in changes if c is not None]
    limit = max_residual_m
    if len(medians) >= 10:
        limit = max(limit, 1.5 * float(np.percentile(medians, 10)))
    runs: list[Run] = []
    current = [0] if stamps_ns else []
    for i in range(1, len(stamps_ns)):
        change = changes[i]
        static = (
            change is not None
            and stamps_ns[i] - stamps_ns[i - 1] <= max_gap_ns
            and change[0] <= limit
            and change[1] >= min_near_fraction
        )
        if static:
            current.append(i)
            continue
        if len(current) >= min_scans:
            runs.append(Run(topic, tuple(current), stamps_ns[current[0]], stamps_ns[current[-1]]))
        current = [i]
    if len(current) >= min_scans:
        runs.append(Run(topic, tuple(current), stamps_ns[current[0]], stamps_ns[current[-1]]))
    return runs


@dataclass
class VehicleStop:
    """One stop of the vehicle: the static run of each LiDAR that saw it."""

    index: int
    start_ns: int
    end_ns: int
    runs: dict[str, Run] = field(default_factory=dict)


def group_stops(runs: list[Run], tolerance_ns: int) -> list[VehicleStop]:
    """Merge runs of different LiDARs that overlap in time (within tolerance) into stops."""
    stops: list[VehicleStop] = []
    for run in sorted(runs, key=lambda r: (r.start_ns, r.topic)):
        last = stops[-1] if stops else None
        if (
            last is not None
            and run.start_ns <= last.end_ns + tolerance_ns
            and run.topic not in last.runs
        ):
            last.runs[run.topic] = run
            last.end_ns = max(last.end_ns, run.end_ns)
            continue
        stops.append(VehicleStop(len(stops), run.start_ns, run.end_ns, {run.topic: run}))
    return stops


def horizontal_fov_deg(points_m: F64, up: F64, bin_deg: float = 2.0) -> float:
    """Horizontal extent of a scan about `up`: occupied azimuth bins times the bin width."""
    up = up / np.linalg.norm(up)
    ref = np.array([1.0, 0.0, 0.0]) if abs(up[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = ref - up * (ref @ up)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up, e1)
    az = np.degrees(np.arctan2(points_m @ e2, points_m @ e1))
    bins = np.unique(np.floor((az + 180.0) / bin_deg).astype(np.int64))
    return float(min(360.0, bins.size * bin_deg))


def wrap_deg(angle: float) -> float:
    """Angle wrapped to [-180, 180)."""
    return (angle + 180.0) % 360.0 - 180.0


@dataclass(frozen=True)
class Choice:
    """Kept and dropped stops (with reasons) of one LiDAR."""

    kept: list[int]
    dropped: dict[int, str]


def choose_stops(
    order: list[int], angles_deg: dict[int, float | None], reference: int, min_step_deg: float
) -> Choice:
    """Keep the reference and every stop at least `min_step_deg` from all kept ones."""
    kept = [reference]
    dropped: dict[int, str] = {}
    for stop in order:
        if stop == reference:
            continue
        angle = angles_deg.get(stop)
        if angle is None:
            dropped[stop] = "angle unknown: no coarse overlap with the neighbouring stops"
            continue
        close = [
            k
            for k in kept
            if (other := angles_deg.get(k)) is not None
            and abs(wrap_deg(angle - other)) < min_step_deg
        ]
        if close:
            gap = abs(wrap_deg(angle - float(angles_deg[close[0]] or 0.0)))
            dropped[stop] = f"only {gap:.1f} deg from stop {close[0]} (< {min_step_deg:g} deg)"
            continue
        kept.append(stop)
    return Choice(kept=sorted(kept), dropped=dropped)


def candidate_pairs(
    kept: list[int],
    angles_deg: dict[int, float | None],
    hfov_deg: float,
    min_predicted_overlap: float,
    max_pairs_per_scan: int,
) -> list[tuple[int, int, float, float]]:
    """(first, second, separation deg, predicted overlap) of stops whose views should overlap.

    The predicted overlap is the shared fraction of the LiDAR's horizontal view after the
    vehicle turned by the separation; each stop pairs with its `max_pairs_per_scan`
    angularly nearest stops.
    """
    partners: dict[int, list[tuple[float, int]]] = {k: [] for k in kept}
    for i, a in enumerate(kept):
        for b in kept[i + 1 :]:
            ang_a, ang_b = angles_deg.get(a), angles_deg.get(b)
            if ang_a is None or ang_b is None:
                continue
            sep = abs(wrap_deg(ang_b - ang_a))
            if 1.0 - sep / hfov_deg >= min_predicted_overlap:
                partners[a].append((sep, b))
                partners[b].append((sep, a))
    chosen: set[tuple[int, int]] = set()
    for a, near in partners.items():
        for _sep, b in sorted(near)[:max_pairs_per_scan]:
            chosen.add((min(a, b), max(a, b)))
    out = []
    for a, b in sorted(chosen):
        ang_a, ang_b = angles_deg[a], angles_deg[b]
        assert ang_a is not None and ang_b is not None
        sep = abs(wrap_deg(ang_b - ang_a))
        out.append((a, b, sep, max(0.0, 1.0 - sep / hfov_deg)))
    return out


def signed_angle_deg(transform: F64, up: F64) -> float:
    """Rotation of a relative pose about the turntable axis `up`, signed, in degrees."""
    return se3.signed_angle_about_deg(transform[:3, :3], up / np.linalg.norm(up))
