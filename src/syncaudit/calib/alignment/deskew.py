"""Deskewing a scan taken while moving: every point re-expressed in the sensor frame at one
instant, given the sensor's motion over the sweep (constant velocity within it).

A spinning LiDAR fires each azimuth at one instant, so a scan's per-point times are a
function of azimuth: `sweep_times` keeps that function as a small table (one time per
0.5 deg bin, a few kB per scan) instead of a time per point, so the voxelised points kept
in memory still get their times. Nothing here assumes which way the sensor spins, where
the sweep starts, or what the header stamp marks (first point, last point, absolute
times): the table holds each bin's time from the stamp as the driver wrote it, and
`refusal` names sweeps whose times cannot be deskewed with (all equal, restarting per
packet, spanning far more than one scan period, not a function of azimuth).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib import se3

F64 = NDArray[np.float64]

BIN_DEG = 0.5
"""Azimuth bin of the time table."""
_MAX_BIN_SPREAD = 0.02
"""A bin whose points' times differ (1-sigma) by more than this share of the sweep mixes
the sweep's start and end (the seam): its time is unknown and its points are dropped."""
_MIN_KNOWN_BINS = 0.5
"""A sweep with fewer known bins than this share of its occupied bins is not spinning."""
_MIN_SPAN_SHARE = 0.05
"""Point times spanning less than this share of the scan period are not a sweep's (all
equal, or restarting per packet: a VLP-16 packet spans 1.3 ms of a 100 ms scan); a LiDAR
cropped to a narrow view still spans its share (the simulator's 120 deg: a third)."""


@dataclass(frozen=True)
class SweepTimes:
    """When each azimuth of one scan was fired: ns from the header stamp per `BIN_DEG` bin
    about the sensor's z axis (NaN: no points there, or the seam)."""

    times_ns: NDArray[np.float32]
    first_ns: float
    last_ns: float
    """The earliest and latest point time from the stamp (ns, as the driver wrote them)."""
    known_share: float
    """Share of the occupied bins whose time is known (1.0 for a clean spinning sweep)."""

    @property
    def span_ns(self) -> float:
        """How long the sweep took."""
        return self.last_ns - self.first_ns

    @property
    def middle_ns(self) -> float:
        """The sweep's middle instant from the stamp: the instant a deskewed scan is at."""
        return 0.5 * (self.first_ns + self.last_ns)


def _bins(points_m: NDArray[np.generic]) -> NDArray[np.int64]:
    pts = np.asarray(points_m, dtype=np.float64)
    azimuth_deg = np.degrees(np.arctan2(pts[:, 1], pts[:, 0])) + 180.0
    n = round(360.0 / BIN_DEG)
    return np.minimum((azimuth_deg / BIN_DEG).astype(np.int64), n - 1)


def sweep_times(points_m: NDArray[np.generic], times_ns: NDArray[np.generic]) -> SweepTimes:
    """The time table of one scan from its points (sensor frame) and per-point times."""
    n = round(360.0 / BIN_DEG)
    times = np.asarray(times_ns, dtype=np.float64)
    bins = _bins(points_m)
    count = np.bincount(bins, minlength=n).astype(np.float64)
    offset = float(np.median(times)) if times.size else 0.0
    centred = times - offset
    total = np.bincount(bins, weights=centred, minlength=n)
    squares = np.bincount(bins, weights=centred * centred, minlength=n)
    occupied = count > 0
    mean = np.full(n, np.nan)
    mean[occupied] = total[occupied] / count[occupied]
    spread = np.zeros(n)
    spread[occupied] = np.sqrt(
        np.maximum(squares[occupied] / count[occupied] - mean[occupied] ** 2, 0.0)
    )
    first = float(times.min()) if times.size else 0.0
    last = float(times.max()) if times.size else 0.0
    seam = spread > _MAX_BIN_SPREAD * max(last - first, 1.0)
    mean[seam] = np.nan
    known = int(np.count_nonzero(np.isfinite(mean)))
    return SweepTimes(
        times_ns=(mean + offset).astype(np.float32),
        first_ns=first,
        last_ns=last,
        known_share=known / max(int(np.count_nonzero(occupied)), 1),
    )


def refusal(sweep: SweepTimes | None, period_ns: float) -> str | None:
    """Why a scan cannot be deskewed (None: it can): no time field, times that do not
    cover about one scan period, or times that are not a function of azimuth."""
    if sweep is None:
        return "the cloud has no per-point time field"
    if sweep.span_ns < _MIN_SPAN_SHARE * period_ns:
        return (
            f"its point times span {sweep.span_ns / 1e6:.2f} ms of a {period_ns / 1e6:.1f} ms "
            "scan period (all equal, or restarting per packet)"
        )
    if sweep.span_ns > 1.5 * period_ns:
        return (
            f"its point times span {sweep.span_ns / 1e6:.1f} ms, over 1.5 scan periods "
            f"({period_ns / 1e6:.1f} ms)"
        )
    if sweep.known_share < _MIN_KNOWN_BINS:
        return (
            f"its point times are not a function of azimuth ({sweep.known_share:.0%} of the "
            "azimuths have one time): not a spinning sweep"
        )
    return None


def point_times_ns(sweep: SweepTimes, points_m: NDArray[np.generic]) -> F64:
    """Each point's time from the stamp (ns) by its azimuth; NaN where the table has none."""
    return np.asarray(sweep.times_ns[_bins(points_m)], dtype=np.float64)


def body_velocity(start_from_end: F64, duration_s: float) -> F64:
    """Constant body velocity (rad/s about, m/s along the sensor's axes, [rotation,
    translation]) that moves the sensor by `start_from_end` in `duration_s`."""
    rotvec = se3.log_so3(start_from_end[:3, :3])
    # The translation part of the SE(3) log: V^-1 t.
    theta = float(np.linalg.norm(rotvec))
    skew = se3.skew(rotvec)
    if theta < 1e-9:
        v_inv = np.eye(3) - 0.5 * skew
    else:
        half = theta / 2.0
        coef = (1.0 - half * math.cos(half) / math.sin(half)) / theta**2
        v_inv = np.eye(3) - 0.5 * skew + coef * skew @ skew
    return np.concatenate([rotvec, v_inv @ start_from_end[:3, 3]]) / duration_s


def motion_at(velocity: F64, dt_s: F64) -> tuple[F64, F64]:
    """The sensor's poses `dt_s` (N,) after the reference instant at constant body
    `velocity`: rotations (N, 3, 3) and translations (N, 3) of ref_from_sensor(t)."""
    xi = dt_s[:, None] * velocity[None, :]
    w, v = xi[:, :3], xi[:, 3:]
    theta = np.linalg.norm(w, axis=1)
    small = theta < 1e-9
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0, np.sin(safe) / safe)
    b = np.where(small, 0.5, (1.0 - np.cos(safe)) / safe**2)
    c = np.where(small, 1.0 / 6.0, (safe - np.sin(safe)) / safe**3)
    k = np.zeros((dt_s.size, 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    k[:, 1, 0], k[:, 2, 0], k[:, 2, 1] = w[:, 2], -w[:, 1], w[:, 0]
    k2 = k @ k
    eye = np.eye(3)[None]
    rot = eye + a[:, None, None] * k + b[:, None, None] * k2
    vmat = eye + b[:, None, None] * k + c[:, None, None] * k2
    return rot, np.einsum("nij,nj->ni", vmat, v)


def deskew(points_m: NDArray[np.generic], dt_s: F64, velocity: F64) -> F64:
    """Points fired `dt_s` (N,) after the reference instant, each in the sensor frame of
    its own instant, re-expressed in the sensor frame at the reference instant."""
    rot, trans = motion_at(velocity, dt_s)
    pts = np.asarray(points_m, dtype=np.float64)
    return np.asarray(np.einsum("nij,nj->ni", rot, pts) + trans)


def deskew_scan(
    points_m: NDArray[np.generic], sweep: SweepTimes, velocity: F64
) -> tuple[F64, float]:
    """A scan's points at its sweep's middle instant (the points of unknown time dropped),
    and that instant (ns from the stamp)."""
    times = point_times_ns(sweep, points_m)
    keep = np.isfinite(times)
    dt_s = (times[keep] - sweep.middle_ns) * 1e-9
    return deskew(np.asarray(points_m)[keep], dt_s, velocity), sweep.middle_ns
