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
from typing import Any

import numpy as np
from numpy.typing import NDArray

from syncaudit.columns.lidar import RevolutionColumns
from syncaudit.columns.runs import run_starts
from syncaudit.lidar.samples import PacketSamples

FULL_TURN_DEG = 360.0
MAX_SAMPLE_SPAN_DEG = 30.0
"""A sample covers at most this much of a turn (a packet: 4.8 deg on a VLP-16 at 600 rpm)."""
MAX_BLOCK_STEP_DEG = 90.0
"""Steps larger than this between consecutive blocks are gaps, not rotation samples."""
CROP_BIN_DEG = 5.0
"""Gaps that start within this angle of each other in most revolutions are a cropped sector."""
NO_TURN_BOUND_DEG = 90.0
"""Where the fastest block-to-block rate times the longest moving step's time stays below
this, the gap-turn correction of every moving step is 0 whatever the median rate."""


def _orient(azimuth_deg: NDArray[np.float64], direction: int) -> NDArray[np.float64]:
    """(direction * azimuth) % 360, skipping the float remainder where it changes nothing.

    `x % 360` is `x` itself for every 0 <= x < 360 but -0.0 (which becomes +0.0), so an
    increasing azimuth already in range (every vendor decoder's) is returned as it is;
    NaN fails the range test and takes the remainder like anything else.
    """
    if direction == 1 and azimuth_deg.size:
        lo, hi = float(azimuth_deg.min()), float(azimuth_deg.max())
        in_range = lo >= 0.0 and hi < FULL_TURN_DEG
        if in_range and (lo > 0.0 or not np.signbit(azimuth_deg).any()):
            return azimuth_deg
    oriented: NDArray[np.float64] = (direction * azimuth_deg) % FULL_TURN_DEG
    return oriented


def _gap_turns(
    omega_deg_ns: float, dts: NDArray[np.float64], step: NDArray[np.float64]
) -> NDArray[np.int64]:
    """Whole turns a step hides beyond its forward angle: round((omega * dt - step) / 360)."""
    turns: NDArray[np.int64] = np.round((omega_deg_ns * dts - step) / FULL_TURN_DEG).astype(
        np.int64
    )
    return turns


def _median_int(values: NDArray[np.int64], guess: float) -> float:
    """`float(np.median(values))` of a nonempty int64 array, without the partition when
    `guess` (e.g. the previous chunk's median) is the value at both middle positions.

    The k-th smallest value is v exactly when fewer than k + 1 values are below v and more
    than k are at or below it; np.median is then float(v) (odd size) or
    (float(v) + float(v)) / 2 == float(v) (even size).
    """
    n = values.size
    if n and math.isfinite(guess) and guess == math.floor(guess):
        v = int(guess)
        below = int(np.count_nonzero(values < v))
        upto = int(np.count_nonzero(values <= v))
        if below <= (n - 1) // 2 and n // 2 < upto:
            return float(v)
    return float(np.median(values))


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
    _omega_ratios: NDArray[np.float64] | None = None
    """Rates (deg/ns) whose median is the block rate, until it is first needed."""
    _period_ns: float = math.nan
    _last_packet_ns: int | None = None
    _gap_median_ns: float = math.nan
    """The last chunk's median packet gap: the likely median of the next."""
    _zero: _Rows = field(default_factory=lambda: _Rows(4))
    """(revolution k, zero-crossing time, its packet's sensor and driver stamps); a later
    row of the same k replaces an earlier one."""
    _targets: _Rows = field(default_factory=lambda: _Rows(3))
    """(revolution k, target index j, crossing time); later rows of a (k, j) replace."""
    _offsets_deg: NDArray[np.float64] | None = None
    _counts: _Rows = field(default_factory=lambda: _Rows(3))
    """(revolution k, packets, dropped packets) of each chunk, summed per k at the end."""
    _gaps: list[tuple[int, float, int]] = field(default_factory=list)
    outlier_blocks: int = 0
    """Blocks ignored because their azimuth contradicts the rest of their packet."""
    _first_unwrapped_deg: float | None = None
    _last_step_deg: float = 0.0
    """The last sample's own span (its step from the one before): the turn a sample covers."""

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
        oriented = _orient(samples.sample_azimuth_deg, self.direction)
        turns = self._turns(times, oriented)
        unwrapped = oriented + FULL_TURN_DEG * turns
        if self._first_unwrapped_deg is None:
            self._first_unwrapped_deg = float(unwrapped[0])
        if unwrapped.size >= 2:
            step = float(unwrapped[-1] - unwrapped[-2])
        elif self._carry is not None:
            step = float(unwrapped[-1]) - self._carry.unwrapped_deg
        else:
            step = 0.0
        if 0.0 < step < MAX_SAMPLE_SPAN_DEG:  # a gap's step is no sample's span
            self._last_step_deg = step
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
        moving_dts = dts[moving]
        ratios = step[moving] / moving_dts
        if ratios.size:
            self._omega_ratios = ratios  # the block rate: their median, taken when needed
            self._add_gap_turns(wraps, dts, step, moving, ratios, float(moving_dts.max()))
        elif math.isfinite(self._omega()):
            wraps += _gap_turns(self._omega(), dts, step)
        turns: NDArray[np.int64] = prev_turns + np.cumsum(wraps)
        return turns

    def _omega(self) -> float:
        """The block rate (deg/ns): median of the last chunk's moving rates; NaN before any."""
        if self._omega_ratios is not None:
            self._omega_deg_ns = float(np.median(self._omega_ratios))
            self._omega_ratios = None
        return self._omega_deg_ns

    def _add_gap_turns(
        self,
        wraps: NDArray[np.int64],
        dts: NDArray[np.float64],
        step: NDArray[np.float64],
        moving: NDArray[np.bool_],
        ratios: NDArray[np.float64],
        max_moving_dt: float,
    ) -> None:
        """wraps += _gap_turns(median of `ratios`, dts, step), mostly without the median.

        The median lies in [min, max] of `ratios` (the mean of two middle values too), and
        round((w * dt - step) / 360) is monotonic in w for each sample (every float step is
        monotonic), so where it is the same at both ends it is the value at the median.
        For moving samples (0 < step < 90, 0 < dt) it is 0 at both ends as soon as
        max * longest dt < 90: then -90 < w * dt - step < 90. Only the other samples (gaps,
        repeats: a few) are evaluated at both ends, and the median taken only if they differ.
        """
        lo, hi = float(ratios.min()), float(ratios.max())
        if not hi * max_moving_dt < NO_TURN_BOUND_DEG:
            wraps += _gap_turns(self._omega(), dts, step)
            return
        others = np.flatnonzero(~moving)
        if not others.size:
            return
        dt_o, step_o = dts[others], step[others]
        at_lo = _gap_turns(lo, dt_o, step_o)
        if not np.array_equal(at_lo, _gap_turns(hi, dt_o, step_o)):
            at_lo = _gap_turns(self._omega(), dt_o, step_o)
        wraps[others] += at_lo

    def _count_packets(
        self,
        sensor_ns: NDArray[np.int64],
        unwrapped: NDArray[np.float64],
        packet_of: NDArray[np.int64],
    ) -> None:
        """Packets per revolution, and packets missing from gaps in the sensor-time cadence."""
        first = run_starts(packet_of)  # packet_of is nondecreasing from packet_samples
        if first is None:
            packets, first = np.unique(packet_of, return_index=True)
        else:
            packets = packet_of[first]
        rev = np.floor((unwrapped[first] - self._zero_oriented) / FULL_TURN_DEG).astype(np.int64)
        stamps = sensor_ns[packets]
        prev = self._last_packet_ns
        gaps = np.diff(stamps if prev is None else np.concatenate(([prev], stamps)))
        positive = gaps[gaps > 0]
        if positive.size:
            median = self._gap_median_ns = _median_int(positive, self._gap_median_ns)
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
        self._counts.add(*_per_revolution(rev, missing))
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
        packet = packet_of[at_zero]
        own = np.maximum(packet, 0)
        zero_sensor, zero_driver = sensor_ns[own], driver_ns[own]
        if self._carry is not None:  # packet -1: the carried sample's packet
            zero_sensor = np.where(packet < 0, self._carry.packet_sensor_ns, zero_sensor)
            zero_driver = np.where(packet < 0, self._carry.packet_driver_ns, zero_driver)
        self._zero.add(ks[zero], t_cross[zero], zero_sensor, zero_driver)
        self._targets.add(ks[~zero], j_of[~zero] - 1, t_cross[~zero])

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
    def whole_turns(self) -> int:
        """Whole turns swept from the first sample to the end of the last (gaps' hidden
        turns included): one frame of 64 Ouster packets of 16 columns is one turn.

        The revolution count of a topic: unlike the zero crossings it does not depend on
        where the rig puts the zero azimuth.
        """
        if self._carry is None or self._first_unwrapped_deg is None:
            return 0
        swept = self._carry.unwrapped_deg - self._first_unwrapped_deg + self._last_step_deg
        return int(swept // FULL_TURN_DEG)

    @property
    def omega_blocks_deg_s(self) -> float:
        """Angular velocity from consecutive blocks (works with less than a revolution)."""
        return self._omega() * 1e9

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
        if revolutions < 2 or revolutions < 0.8 * max(self._zero.distinct_keys(), 1):
            return None
        return (
            float(np.median([g[1] for g in best])),
            float(np.median([g[2] for g in best])),
            revolutions,
        )

    def finish(self) -> RevolutionColumns:
        """Per-revolution columns for every revolution whose start was seen."""
        zk, zero, zero_sensor, zero_driver = self._zero.last_per_key()
        # Packets and drops of the revolutions whose start was seen, summed over chunks.
        ck, counts, drops = self._counts.columns()
        at, seen = _positions(zk, ck)
        packets = np.bincount(at[seen], weights=counts[seen], minlength=zk.size).astype(np.int64)
        dropped = np.bincount(at[seen], weights=drops[seen], minlength=zk.size).astype(np.int64)
        crop = self.cropped_sector()
        if crop is not None and zk.size:
            centre = round(crop[0] / CROP_BIN_DEG)
            for k, angle, missing in self._gaps:
                i = int(np.searchsorted(zk, k))
                if round(angle / CROP_BIN_DEG) == centre and i < zk.size and zk[i] == k:
                    dropped[i] -= missing
        omega = np.full(zk.size, np.nan)
        if zk.size > 1:
            consecutive = np.diff(zk) == 1
            period_s = np.diff(zero).astype(np.float64) / 1e9
            omega[:-1] = np.where(consecutive, FULL_TURN_DEG / period_s, np.nan)
        n_targets = len(self.target_azimuth_deg)
        crossings = np.full((zk.size, n_targets), -1, dtype=np.int64)
        tk, tj, tt = self._targets.last_per_key(keys=2)
        row, mine = _positions(zk, tk)
        crossings[row[mine], tj[mine]] = tt[mine]
        return RevolutionColumns(
            zero_crossing_sensor_ns=zero,
            omega_deg_s=omega,
            packets=packets,
            dropped_packets=dropped,
            crossing_sensor_ns=crossings,
            target_azimuth_deg=np.array(self.target_azimuth_deg, dtype=np.float64),
            zero_packet_sensor_ns=zero_sensor,
            zero_packet_driver_ns=zero_driver,
        )


def _positions(
    keys: NDArray[np.int64], wanted: NDArray[np.int64]
) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
    """Where each wanted value sits in the sorted distinct `keys`, and whether it is there."""
    at = np.searchsorted(keys, wanted)
    if not keys.size:
        return at, np.zeros(wanted.size, dtype=bool)
    found: NDArray[np.bool_] = keys[np.minimum(at, keys.size - 1)] == wanted
    return at, found


class _Rows:
    """Rows of int64 columns appended a chunk at a time, kept as a few numpy arrays: a
    revolution costs 8 bytes a column (a dict entry of Python ints cost ~10x that)."""

    __slots__ = ("_done", "_parts", "width")

    MERGE_PARTS = 64
    """Chunks gathered before they are joined into one array per column."""

    def __init__(self, width: int) -> None:
        self.width = width
        self._parts: list[tuple[NDArray[np.int64], ...]] = []
        self._done: tuple[NDArray[np.int64], ...] = tuple(
            np.empty(0, dtype=np.int64) for _ in range(width)
        )

    def add(self, *columns: NDArray[Any]) -> None:
        """Append rows (one array per column, equal lengths; values taken as int64)."""
        if columns[0].size:
            self._parts.append(tuple(np.asarray(c).astype(np.int64) for c in columns))
            if len(self._parts) >= self.MERGE_PARTS:
                self.columns()

    def columns(self) -> tuple[NDArray[np.int64], ...]:
        """Every row so far, in the order added, one array per column."""
        if self._parts:
            self._done = tuple(
                np.concatenate([self._done[i], *(p[i] for p in self._parts)])
                for i in range(self.width)
            )
            self._parts = []
        return self._done

    def last_per_key(self, keys: int = 1) -> tuple[NDArray[np.int64], ...]:
        """The rows sorted by their first `keys` columns, one per key: the last added."""
        cols = self.columns()
        n = cols[0].size
        if not n:
            return cols
        # lexsort sorts by its last key first; ties keep their order, so the last row of
        # each key is the last of its run.
        order = np.lexsort((np.arange(n), *reversed(cols[:keys])))
        ordered = [c[order] for c in cols]
        last = np.ones(n, dtype=bool)
        if n > 1:
            same = np.ones(n - 1, dtype=bool)
            for c in ordered[:keys]:
                same &= c[1:] == c[:-1]
            last[:-1] = ~same
        return tuple(c[last] for c in ordered)

    def distinct_keys(self) -> int:
        """Rows with distinct first columns."""
        return int(np.unique(self.columns()[0]).size)


def _per_revolution(
    rev: NDArray[np.int64], missing: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """The distinct revolutions of a chunk's packets, packets and missing packets in each.

    Revolution numbers are nondecreasing but where the angle steps back across a
    boundary; runs of equal numbers then give what `np.unique` and `np.bincount` give.
    """
    starts = run_starts(rev)
    if starts is None:
        revs, inverse = np.unique(rev, return_inverse=True)
        counts = np.bincount(inverse)
        drops = np.bincount(inverse, weights=missing).astype(np.int64)
        return revs, counts, drops
    counts = np.diff(starts, append=rev.size)
    return rev[starts], counts, np.add.reduceat(missing, starts)
