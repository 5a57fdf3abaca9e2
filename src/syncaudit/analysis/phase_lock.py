"""Phase-lock health: when the LiDAR crosses its locked azimuth against the top of each second.

A phase-locked LiDAR (Velodyne phase lock, Hesai sync angle, Ouster phase_lock_offset)
crosses the lock azimuth at the top of every second, and at every revolution period after
it (100 ms at 600 rpm). Per revolution the offset is the crossing time less the nearest
such grid time (sensor clock); a run of revolutions off by more than `LOCK_TOLERANCE_DEG`
of rotation is a lost lock, shown where it happened.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

NS_PER_S = 1_000_000_000
MIN_REVOLUTIONS = 20
"""Fewer revolutions (2 s at 600 rpm) cannot tell a locked LiDAR from a free one whose rate
is close to nominal: 0.01 % off drifts only 10 us a revolution."""
LOCK_TOLERANCE_DEG = 1.0
"""A revolution farther than this (in rotation) from the grid is out of lock (278 us at
600 rpm): ten times the jitter a locked sensor shows."""


def lock_azimuth_at_tos_deg(
    zero_ns: NDArray[np.int64], omega_deg_s: NDArray[np.float64], zero_azimuth_deg: float
) -> float:
    """The azimuth the LiDAR is at on the revolution grid after each top of second (the
    circular median of every revolution's): what its lock angle is set to."""
    period = _grid_period_ns(omega_deg_s)
    grid = np.rint(zero_ns / period) * period
    az = (zero_azimuth_deg + omega_deg_s * (grid - zero_ns) / 1e9) % 360.0
    az = az[np.isfinite(az)]
    if not az.size:
        return math.nan
    angle = np.radians(az)
    mean = float(np.degrees(math.atan2(np.sin(angle).mean(), np.cos(angle).mean())))
    # The median about the circular mean: revolutions out of lock do not pull it.
    deviation = (az - mean + 180.0) % 360.0 - 180.0
    return (mean + float(np.median(deviation))) % 360.0


def _grid_period_ns(omega_deg_s: NDArray[np.float64]) -> float:
    w = omega_deg_s[np.isfinite(omega_deg_s)]
    rate = max(1, round(float(np.median(w)) / 360.0)) if w.size else 10
    return NS_PER_S / rate


def phase_lock_health(
    zero_ns: NDArray[np.int64],
    omega_deg_s: NDArray[np.float64],
    *,
    zero_azimuth_deg: float,
    lock_azimuth_deg: float | None,
    start_ns: int,
) -> dict[str, Any]:
    """Mean, jitter and drift of the lock-azimuth crossings against the grid; lost locks.

    `zero_ns` (sensor clock) and `omega_deg_s` are per revolution; `start_ns` the log start
    on the same clock, for the times of lost locks. Without `lock_azimuth_deg` (the rig's)
    the lock angle is measured.
    """
    ok = np.isfinite(omega_deg_s) & (omega_deg_s > 0)
    zero, omega = zero_ns[ok], omega_deg_s[ok]
    if zero.size < MIN_REVOLUTIONS:
        return {
            "judged": False,
            "why": f"{zero.size} revolutions with a rate: at least {MIN_REVOLUTIONS} are needed "
            "to tell a phase-locked LiDAR from a free one",
        }
    measured = lock_azimuth_at_tos_deg(zero, omega, zero_azimuth_deg)
    lock = measured if lock_azimuth_deg is None else lock_azimuth_deg
    period = _grid_period_ns(omega)
    cross = zero + ((lock - zero_azimuth_deg) % 360.0) / omega * 1e9
    offset = cross - np.rint(cross / period) * period
    offset = (offset + period / 2) % period - period / 2
    tolerance_ns = LOCK_TOLERANCE_DEG / float(np.median(omega)) * 1e9
    out_of_lock = np.abs(offset) > tolerance_ns
    t_s = (zero - start_ns) / 1e9
    drift = float(np.polyfit(t_s, offset, 1)[0]) if t_s.size >= 3 else math.nan
    locked_share = 1.0 - float(out_of_lock.mean())
    return {
        "judged": True,
        "lock_azimuth_deg": round(lock, 3),
        "lock_azimuth_source": "rig" if lock_azimuth_deg is not None else "measured",
        "measured_azimuth_at_tos_deg": round(measured, 3),
        "offset_mean_us": round(float(offset.mean()) / 1e3, 3),
        "jitter_us": round(float(offset.std()) / 1e3, 3),
        "drift_us_per_s": round(drift / 1e3, 3) if math.isfinite(drift) else None,
        "tolerance_us": round(tolerance_ns / 1e3, 3),
        "locked_fraction": round(locked_share, 4),
        "locked": bool(locked_share >= 0.99),
        "lost_lock": _spans(out_of_lock, t_s, offset) if locked_share >= 0.5 else [],
    }


def _spans(
    bad: NDArray[np.bool_], t_s: NDArray[np.float64], offset_ns: NDArray[np.float64]
) -> list[dict[str, float]]:
    """Runs of revolutions out of lock: when (log seconds) and how far."""
    spans: list[dict[str, float]] = []
    edges = np.flatnonzero(np.diff(np.concatenate(([0], bad.astype(np.int8), [0]))))
    for lo, hi in zip(edges[::2], edges[1::2], strict=True):
        spans.append(
            {
                "start_s": round(float(t_s[lo]), 3),
                "end_s": round(float(t_s[hi - 1]), 3),
                "revolutions": int(hi - lo),
                "max_offset_us": round(float(np.abs(offset_ns[lo:hi]).max()) / 1e3, 3),
            }
        )
    return spans
