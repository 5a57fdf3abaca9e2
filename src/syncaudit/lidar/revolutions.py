"""Revolutions of a spinning LiDAR from its packets' (sensor time, azimuth) trajectory.

The tracker is fed decoded packets chunk by chunk (a scan message at a time) and keeps
only per-revolution state, so memory stays flat however long the log. It unwraps the
azimuth into a monotonic angle, finds every crossing of the zero-crossing azimuth (the
revolution boundaries) and of each target azimuth (camera centres) by linear
interpolation between blocks, and counts packets and cadence gaps per revolution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from syncaudit.columns.distinct import distinct
from syncaudit.columns.lidar import RevolutionColumns
from syncaudit.lidar.samples import PacketSamples

FULL_TURN_DEG = 360.0
MAX_BLOCK_STEP_DEG = 90.0
"""Steps larger than this between consecutive blocks are gaps, not rotation samples."""
CROP_BIN_DEG = 5.0
"""Gaps that start within this angle of each other in most revolutions are a cropped sector."""


def _interpolate(
    angles: NDArray[np.float64],
    unwrapped: NDArray[np.float64],
    times: NDArray[np.int64],
    at: NDArray[np.intp],
) -> NDArray[np.int64]:
    """Time of each angle, linear between the samples around it (`at`: first at/after).

    Local to the two samples, in integer nanoseconds from the earlier one, so the result
    does not depend on what else is in the chunk.
    """
    right = np.clip(at, 1, unwrapped.size - 1)
    left = right - 1
    span = unwrapped[right] - unwrapped[left]
    safe = np.where(span > 0, span, 1.0)
    fraction = np.clip(np.where(span > 0, (angles - unwrapped[left]) / safe, 1.0), 0.0, 1.0)
    dt = (times[right] - times[left]).astype(np.float64)
    crossing: NDArray[np.int64] = times[left] + np.rint(fraction * dt).astype(np.int64)
    return crossing


@dataclass(slots=True)
class _Carry:
    """The last sample of the previous chunk, so interpolation spans chunk borders."""

    time_ns: int
    oriented_deg: float
    turns: int
    packet_sensor_ns: int
    packet_driver_ns: int

    @property
    def unwrapped_deg(self) -> float:
        """The sample's unwrapped angle, computed exactly as `_unwrap` computes it."""
        return self.oriented_deg + FULL_TURN_DEG * self.turns


@dataclass(slots=True)
class RevolutionTracker:
    """Streaming revolution finder; `feed` packets in time order, then `finish`."""

    zero_azimuth_deg: float = 0.0
    direction: int = 1
    """+1 where the vendor azimuth grows with rotation, -1 where it shrinks."""
    target_azimuth_deg: tuple[float, ...] = ()
    _carry: _Carry | None = None
    _omega_deg_ns: float = math.nan
    _period_ns: float = math.nan
    _last_packet_ns: int | None = None
    _zero: dict[int, tuple[int, int, int]] = field(default_factory=dict)
    _targets: dict[int, NDArray[np.int64]] = field(default_factory=dict)
    """Per revolution k: each target's crossing time (-1 where not seen)."""
    _offsets_deg: NDArray[np.float64] | None = None
    _packets: dict[int, int] = field(default_factory=dict)
    _dropped: dict[int, int] = field(default_factory=dict)
    _gaps: list[tuple[int, float, int]] = field(default_factory=list)
    outlier_blocks: int = 0
    """Blocks ignored because their azimuth contradicts the rest of their packet."""

    def __post_init__(self) -> None:
        if self.direction not in (1, -1):
            raise ValueError("direction must be +1 or -1")

    @property
    def _zero_oriented(self) -> float:
        return (self.direction * self.zero_azimuth_deg) % FULL_TURN_DEG

    def feed(self, samples: PacketSamples) -> None:
        """Add one chunk of packets (in time order), reduced to samples."""
        self.outlier_blocks += samples.outlier_blocks
        times = samples.sample_time_ns
        if times.size == 0:
            return
        packet_of = samples.sample_packet
        oriented = (self.direction * samples.sample_azimuth_deg) % FULL_TURN_DEG
        turns = self._turns(times, oriented)
        unwrapped = oriented + FULL_TURN_DEG * turns
        self._count_packets(samples.sensor_time_ns, unwrapped, packet_of)
        self._find_crossings(
            times, unwrapped, packet_of, samples.sensor_time_ns, samples.driver_stamp_ns
        )
        last = int(packet_of[-1])
        self._carry = _Carry(
            int(times[-1]),
            float(oriented[-1]),
            int(turns[-1]),
            int(samples.sensor_time_ns[last]),
            int(samples.driver_stamp_ns[last]),
        )

    def _turns(self, times: NDArray[np.int64], oriented: NDArray[np.float64]) -> NDArray[np.int64]:
        """Whole turns before each sample: its unwrapped angle is oriented + 360 * turns.

        Each step is the forward angle, plus whole turns across gaps. Counting turns as
        integers (not summing float steps) makes every unwrapped angle independent of how
        the packets were cut into chunks, so a block exactly at a crossing azimuth falls on
        the same side of it however the log is read.
        """
        if self._carry is None:
            prev_t, prev_o, prev_turns = int(times[0]), float(oriented[0]), 0
        else:
            prev_t, prev_o, prev_turns = (
                self._carry.time_ns,
                self._carry.oriented_deg,
                self._carry.turns,
            )
        delta = np.diff(np.concatenate(([prev_o], oriented)))
        wraps = (delta < 0).astype(np.int64)
        step = delta + FULL_TURN_DEG * wraps
        dts = np.diff(np.concatenate(([prev_t], times))).astype(np.float64)
        moving = (dts > 0) & (step > 0) & (step < MAX_BLOCK_STEP_DEG)
        if np.any(moving):
            self._omega_deg_ns = float(np.median(step[moving] / dts[moving]))
        if math.isfinite(self._omega_deg_ns):
            expected = self._omega_deg_ns * dts
            wraps += np.round((expected - step) / FULL_TURN_DEG).astype(np.int64)
        turns: NDArray[np.int64] = prev_turns + np.cumsum(wraps)
        return turns

    def _count_packets(
        self,
        sensor_ns: NDArray[np.int64],
        unwrapped: NDArray[np.float64],
        packet_of: NDArray[np.int64],
    ) -> None:
        """Packets per revolution, and packets missing from gaps in the sensor-time cadence."""
        packets, first = np.unique(packet_of, return_index=True)
        rev = np.floor((unwrapped[first] - self._zero_oriented) / FULL_TURN_DEG).astype(np.int64)
        stamps = sensor_ns[packets]
        prev = self._last_packet_ns
        gaps = np.diff(stamps if prev is None else np.concatenate(([prev], stamps)))
        positive = gaps[gaps > 0]
        if positive.size:
            median = float(np.median(positive))
            self._period_ns = (
                median if not math.isfinite(self._period_ns) else min(median, self._period_ns)
            )
        missing = np.zeros(stamps.size, dtype=np.int64)
        if math.isfinite(self._period_ns) and gaps.size:
            miss = np.maximum(np.rint(gaps / self._period_ns).astype(np.int64) - 1, 0)
            missing[stamps.size - miss.size :] = miss
        for i in np.flatnonzero(missing).tolist():
            angle = float((unwrapped[first[i]] - self._zero_oriented) % FULL_TURN_DEG)
            self._gaps.append((int(rev[i]), angle, int(missing[i])))
        revs, inverse = np.unique(rev, return_inverse=True)
        counts = np.bincount(inverse)
        drops = np.bincount(inverse, weights=missing).astype(np.int64)
        for k, count, drop in zip(revs.tolist(), counts.tolist(), drops.tolist(), strict=True):
            self._packets[k] = self._packets.get(k, 0) + count
            self._dropped[k] = self._dropped.get(k, 0) + drop
        self._last_packet_ns = int(stamps[-1])

    def _find_crossings(
        self,
        times: NDArray[np.int64],
        unwrapped: NDArray[np.float64],
        packet_of: NDArray[np.int64],
        sensor_ns: NDArray[np.int64],
        driver_ns: NDArray[np.int64],
    ) -> None:
        """Record zero crossings (revolution starts) and target crossings in this span."""
        if self._carry is not None:
            times = np.concatenate(([self._carry.time_ns], times))
            unwrapped = np.concatenate(([self._carry.unwrapped_deg], unwrapped))
            packet_of = np.concatenate(([-1], packet_of))
        z = self._zero_oriented
        lo, hi = float(unwrapped[0]), float(unwrapped[-1])
        # Every boundary (j = 0: the zero crossing, j > 0: target j - 1) at once: the
        # revolutions k whose crossing angle falls in [lo, hi], flattened to (j, k) pairs,
        # so the work per chunk is a few numpy calls however many cameras the rig has.
        offsets = self._offsets()
        k_lo = np.ceil((lo - z - offsets) / FULL_TURN_DEG).astype(np.int64)
        k_hi = np.floor((hi - z - offsets) / FULL_TURN_DEG).astype(np.int64)
        counts = np.maximum(k_hi - k_lo + 1, 0)
        if not counts.any():
            return
        j_of = np.repeat(np.arange(offsets.size), counts)
        first = np.repeat(np.cumsum(counts) - counts, counts)
        ks = np.repeat(k_lo, counts) + (np.arange(j_of.size) - first)
        angles = (z + offsets[j_of] + FULL_TURN_DEG * ks).astype(np.float64)
        at = np.searchsorted(unwrapped, angles, side="left")  # first sample at/after
        t_cross = _interpolate(angles, unwrapped, times, at)
        zero = j_of == 0
        at_zero = np.minimum(at[zero], packet_of.size - 1)
        for k, t, p in zip(
            ks[zero].tolist(), t_cross[zero].tolist(), packet_of[at_zero].tolist(), strict=True
        ):
            if p < 0 and self._carry is not None:
                self._zero[k] = (t, self._carry.packet_sensor_ns, self._carry.packet_driver_ns)
            else:
                self._zero[k] = (t, int(sensor_ns[p]), int(driver_ns[p]))
        target_k, target_j, target_t = ks[~zero], j_of[~zero] - 1, t_cross[~zero]
        n_targets = offsets.size - 1
        for k in distinct(target_k).tolist():
            row = self._targets.get(k)
            if row is None:
                row = self._targets[k] = np.full(n_targets, -1, dtype=np.int64)
            mine = target_k == k
            row[target_j[mine]] = target_t[mine]

    def _offsets(self) -> NDArray[np.float64]:
        """Angle of each boundary past the zero crossing: 0, then each target's."""
        if self._offsets_deg is None or self._offsets_deg.size != len(self.target_azimuth_deg) + 1:
            z = self._zero_oriented
            self._offsets_deg = np.array(
                [0.0] + [(self.direction * t - z) % FULL_TURN_DEG for t in self.target_azimuth_deg],
                dtype=np.float64,
            )
        return self._offsets_deg

    @property
    def omega_blocks_deg_s(self) -> float:
        """Angular velocity from consecutive blocks (works with less than a revolution)."""
        return self._omega_deg_ns * 1e9

    def cropped_sector(self) -> tuple[float, float, int] | None:
        """(end angle of the recorded sector, missing packets per turn, revolutions) where the
        same gap recurs in most revolutions: a FOV-cropped recording, not packet loss."""
        if not self._gaps:
            return None
        bins: dict[int, list[tuple[int, float, int]]] = {}
        for gap in self._gaps:
            bins.setdefault(round(gap[1] / CROP_BIN_DEG), []).append(gap)
        best = max(bins.values(), key=len)
        revolutions = len({g[0] for g in best})
        if revolutions < 2 or revolutions < 0.8 * max(len(self._zero), 1):
            return None
        return (
            float(np.median([g[1] for g in best])),
            float(np.median([g[2] for g in best])),
            revolutions,
        )

    def finish(self) -> RevolutionColumns:
        """Per-revolution columns for every revolution whose start was seen."""
        crop = self.cropped_sector()
        if crop is not None:
            centre = round(crop[0] / CROP_BIN_DEG)
            for k, angle, missing in self._gaps:
                if round(angle / CROP_BIN_DEG) == centre:
                    self._dropped[k] -= missing
        ks = sorted(self._zero)
        zero = np.array([self._zero[k][0] for k in ks], dtype=np.int64)
        omega = np.full(len(ks), np.nan)
        if len(ks) > 1:
            consecutive = np.diff(np.array(ks)) == 1
            period_s = np.diff(zero).astype(np.float64) / 1e9
            omega[:-1] = np.where(consecutive, FULL_TURN_DEG / period_s, np.nan)
        n_targets = len(self.target_azimuth_deg)
        unseen = np.full(n_targets, -1, dtype=np.int64)
        crossings = (
            np.stack([self._targets.get(k, unseen) for k in ks])
            if ks
            else np.empty((0, n_targets), dtype=np.int64)
        )
        return RevolutionColumns(
            zero_crossing_sensor_ns=zero,
            omega_deg_s=omega,
            packets=np.array([self._packets.get(k, 0) for k in ks], dtype=np.int64),
            dropped_packets=np.array([self._dropped.get(k, 0) for k in ks], dtype=np.int64),
            crossing_sensor_ns=crossings,
            target_azimuth_deg=np.array(self.target_azimuth_deg, dtype=np.float64),
            zero_packet_sensor_ns=np.array([self._zero[k][1] for k in ks], dtype=np.int64),
            zero_packet_driver_ns=np.array([self._zero[k][2] for k in ks], dtype=np.int64),
        )
