"""Sensor clock vs host clock, from each packet's driver stamp minus its sensor time.

That difference is t1 (network + driver latency) plus whatever offset separates the
LiDAR's clock from the host's. With synchronised clocks it is a small positive latency;
otherwise the offset dominates, and the latency spread is recovered by removing the
minimum (a minimum filter: the fastest packets had near-zero queueing).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from syncaudit.columns.lidar import ClockReport

SAMPLE_CAP = 131_072
"""Differences kept for quantiles; beyond it the sample is decimated, so memory is flat."""
SYNC_FLOOR_NS = -1_000_000
"""A driver stamp more than 1 ms before the sensor time means the clocks disagree."""


@dataclass(slots=True)
class ClockEstimator:
    """Streaming statistics of driver stamp minus sensor time, memory bounded."""

    tolerance_ns: int = 50_000_000
    _count: int = 0
    _sum: float = 0.0
    _sumsq: float = 0.0
    _min: int = np.iinfo(np.int64).max
    _max: int = np.iinfo(np.int64).min
    _stride: int = 1
    _phase: int = 0
    _sample: list[NDArray[np.int64]] = field(default_factory=list)
    _sample_size: int = 0
    _ref: int | None = None

    def feed(self, driver_stamp_ns: NDArray[np.int64], sensor_time_ns: NDArray[np.int64]) -> None:
        """Add one chunk of packets."""
        raw = driver_stamp_ns - sensor_time_ns
        if raw.size == 0:
            return
        if self._ref is None:
            self._ref = int(raw[0])
        rel = (raw - self._ref).astype(np.float64)
        self._count += raw.size
        self._sum += float(rel.sum())
        self._sumsq += float(np.square(rel).sum())
        self._min = min(self._min, int(raw.min()))
        self._max = max(self._max, int(raw.max()))
        # Every stride-th difference counting on from the last chunk's: the indices i with
        # (i + phase) % stride == 0 (copied: a view would keep all of `raw` alive).
        kept = (
            raw if self._stride == 1 else raw[(-self._phase) % self._stride :: self._stride].copy()
        )
        self._phase = (self._phase + raw.size) % self._stride
        self._sample.append(kept)
        self._sample_size += kept.size
        if self._sample_size > SAMPLE_CAP:
            merged = np.concatenate(self._sample)[::2]
            self._sample, self._sample_size, self._stride = [merged], merged.size, self._stride * 2

    def finish(self) -> ClockReport | None:
        """The report, or None when no packet was fed."""
        if self._count == 0 or self._ref is None:
            return None
        sample = np.concatenate(self._sample)
        mean_rel = self._sum / self._count
        var = max(self._sumsq / self._count - mean_rel**2, 0.0)
        median = int(np.median(sample))
        synchronised = self._min >= SYNC_FLOOR_NS and median <= self.tolerance_ns
        offset = 0 if synchronised else self._min
        t1 = (sample - offset).astype(np.float64)
        return ClockReport(
            packets=self._count,
            raw_min_ns=self._min,
            raw_median_ns=median,
            raw_max_ns=self._max,
            raw_mean_ns=self._ref + mean_rel,
            synchronised=synchronised,
            offset_ns=offset,
            t1_mean_ns=self._ref + mean_rel - offset,
            t1_p50_ns=float(np.percentile(t1, 50)),
            t1_p99_ns=float(np.percentile(t1, 99)),
            t1_std_ns=float(np.sqrt(var)),
        )
