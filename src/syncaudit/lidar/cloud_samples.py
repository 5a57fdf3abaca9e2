"""One PointCloud2 reduced to the timing samples the packet path feeds the revolution tracker.

A cloud has no packets, so its points are cut into *sectors*: bins of SECTOR_NS on one
grid of sensor time (the epoch's), the same whatever cloud or chunk a point is in. Each
sector is one pseudo-packet: its stamp is the grid time (a regular cadence, so a sector
without points is a gap the tracker counts as missing, as it counts lost packets), its
sample the mean time and mean azimuth of its points. Along a linear rotation the mean
azimuth is the azimuth at the mean time, plus the mean of the beams' azimuth offsets (0
where the driver writes the head's azimuth): no per-point loop, no sort, O(n).

The driver stamp of each sector is the cloud's log time less how long before the cloud's
last point the sector's stamp lies: host arrival minus sensor time is then the cloud's
(what the clock check compares), not a sector's age within the revolution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from syncaudit.errors import DecodeError
from syncaudit.lidar.cloud_fields import cloud_time, point_azimuth_deg, point_times_ns
from syncaudit.lidar.cloud_layout import cloud_layout
from syncaudit.lidar.samples import PacketSamples
from syncaudit.logs import RawMessage

__all__ = ["SECTOR_NS", "CloudSamples", "CloudSettings", "cloud_samples"]

SECTOR_NS = 1_000_000
"""Width of a sector (ns): 3.6 deg at 600 rpm, ~1 packet of the common sensors."""
POINTS_READ = 40_000
"""At most about this many points of a cloud are read: every k-th point of each row, k
the smallest prime giving so few (k = 7 for a 128-beam cloud of 240k points). A prime
step skips no beam for good (beams per block are powers of two, 40 or 128), so a
sector's mean still averages every beam's azimuth offset; a 1 ms sector keeps hundreds."""
_PRIMES = (1, 2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47, 53, 59, 61, 67, 71)
RESTARTS_PER_ROW = 2
"""More time restarts than this per cloud row: the times restart per packet, not per cloud."""

StampMarks = Literal["first", "last"]


@dataclass(frozen=True, slots=True)
class CloudSettings:
    """How to read a cloud topic's timing (picklable for reader workers)."""

    x_axis_azimuth_deg: float = 0.0
    """Packet azimuth of the cloud frame's +X (for clouds without an azimuth field)."""
    clockwise: bool = True
    """Packet azimuth grows clockwise seen from above."""
    time_field: str | None = None
    """The per-point time field; None: the first known one present."""
    stamp_marks: StampMarks | None = None
    """What the header stamp marks where times are relative and >= 0: 'first' (the
    default: times count from it) or 'last' (the last point is at the stamp)."""
    vendor: str = "cloud"
    model: str = "PointCloud2"


@dataclass(frozen=True, slots=True)
class CloudSamples:
    """A cloud's sectors as packet samples, and what its times said."""

    samples: PacketSamples
    points: int
    """Points read that have a time and an azimuth (every `read_stride`-th point)."""
    first_ns: int
    last_ns: int
    """Sensor time of the cloud's first and last valid point."""
    stamp_ns: int
    time_field: str
    log_time_ns: int = 0
    """When the cloud was logged (host clock)."""


def cloud_samples(msg: RawMessage, settings: CloudSettings) -> CloudSamples | None:
    """The sectors of one PointCloud2 message (None: no point with a time and an azimuth).

    Raises DecodeError (one line) where the cloud is damaged, has no time field, or its
    times restart with every packet (relative to each packet, not to the cloud).
    """
    layout = cloud_layout(msg)
    if layout.n_points == 0:
        return None
    data = msg.data
    time = cloud_time(layout, settings.time_field)
    stride = read_stride(layout.n_points)
    t_ns, base_ns = point_times_ns(layout, data, time, stride)
    _check_restarts(msg.topic, t_ns, layout.height, time.name)
    azimuth = point_azimuth_deg(
        layout, data, settings.x_axis_azimuth_deg, settings.clockwise, stride
    )
    valid = np.isfinite(t_ns) & np.isfinite(azimuth)
    if not valid.any():
        return None
    t = t_ns[valid]
    az = azimuth[valid]
    origin = layout.stamp_ns if base_ns is None else base_ns
    if base_ns is None and settings.stamp_marks == "last" and float(t.max()) > 0:
        origin -= round(float(t.max()))
    return _sectors(msg, layout.stamp_ns, origin, t, az, settings, time.name)


def read_stride(n_points: int) -> int:
    """Every how many points a cloud of `n_points` is read (see POINTS_READ)."""
    wanted = -(-n_points // POINTS_READ)
    return next((p for p in _PRIMES if p >= wanted), _PRIMES[-1])


def _check_restarts(topic: str, t_ns: NDArray[np.float64], rows: int, name: str) -> None:
    """DecodeError where times restart far more often than once a row (per packet)."""
    flat = t_ns.reshape(-1)
    finite = flat[np.isfinite(flat)]
    if finite.size < 2:
        return
    span = float(finite.max() - finite.min())
    restarts = int(np.count_nonzero(np.diff(finite) < -0.5 * span))
    if restarts > RESTARTS_PER_ROW * rows + 1:
        longest = _longest_run_ns(finite)
        raise DecodeError(
            f"{topic}: per-point {name} restarts {restarts} times in one cloud (each run "
            f"spans <= {longest / 1e6:.2f} ms of the cloud's {span / 1e6:.2f} ms): the driver "
            "wrote times relative to each packet, not to the cloud, so the revolution's "
            "timing cannot be read from it; audit the packets, or a driver version that "
            "writes cloud-relative times"
        )


def _with_ends(
    time_ns: NDArray[np.int64], azimuth_deg: NDArray[np.float64], first_ns: int, last_ns: int
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.int64]]:
    """The sector samples plus the cloud's first and last point times, their azimuths
    extrapolated from the end sectors at the cloud's median rate (as a packet's first and
    last block do, a crossing in the cloud's last sector is then found in this cloud).

    Returns times, azimuths (unwrapped near the sectors') and each sample's sector."""
    packet = np.arange(time_ns.size, dtype=np.int64)
    if time_ns.size < 2:
        return time_ns, azimuth_deg, packet
    step = (np.diff(azimuth_deg) + 180.0) % 360.0 - 180.0
    dt = np.diff(time_ns).astype(np.float64)
    rate = float(np.median(step[dt > 0] / dt[dt > 0])) if (dt > 0).any() else 0.0
    head, tail = [], []
    if first_ns < time_ns[0]:
        head = [(first_ns, azimuth_deg[0] + rate * (first_ns - int(time_ns[0])), 0)]
    if last_ns > time_ns[-1]:
        tail = [(last_ns, azimuth_deg[-1] + rate * (last_ns - int(time_ns[-1])), packet[-1])]
    if not head and not tail:
        return time_ns, azimuth_deg, packet
    t = np.concatenate(([h[0] for h in head], time_ns, [e[0] for e in tail])).astype(np.int64)
    az = np.concatenate(([h[1] for h in head], azimuth_deg, [e[1] for e in tail]))
    pk = np.concatenate(([h[2] for h in head], packet, [e[2] for e in tail])).astype(np.int64)
    return t, az, pk


def _longest_run_ns(values: NDArray[np.float64]) -> float:
    """The longest time span of a run of non-decreasing values."""
    starts = np.concatenate(([0], np.flatnonzero(np.diff(values) < 0) + 1))
    spans = np.maximum.reduceat(values, starts) - np.minimum.reduceat(values, starts)
    return float(spans.max())


def _sectors(
    msg: RawMessage,
    stamp_ns: int,
    origin_ns: int,
    t_rel: NDArray[np.float64],
    azimuth: NDArray[np.float64],
    settings: CloudSettings,
    time_name: str,
) -> CloudSamples:
    """Mean time and azimuth of the points in each sector of the grid.

    Times stay float64 ns after `origin_ns` (exact to far below a ns over a cloud); the
    grid is placed by the origin's integer remainder, so sectors are the epoch's.
    """
    first_sector, remainder = divmod(origin_ns, SECTOR_NS)
    t_grid = t_rel + float(remainder)  # ns after the start of sector `first_sector`
    lowest = math.floor(float(t_grid.min()) / SECTOR_NS)
    first_sector += lowest
    t_grid -= lowest * SECTOR_NS
    index = (t_grid * (1.0 / SECTOR_NS)).astype(np.intp)  # >= 0: a truncation is a floor
    counts = np.bincount(index)
    present = np.flatnonzero(counts)
    n = counts[present]
    mean_grid = np.bincount(index, weights=t_grid)[present] / n
    reference = np.zeros(counts.size)
    reference[index] = azimuth  # any point of the sector: the wrap reference
    offset = azimuth - reference[index]
    offset[offset > 180.0] -= 360.0
    offset[offset < -180.0] += 360.0
    sample_az = reference[present] + np.bincount(index, weights=offset)[present] / n
    base = first_sector * SECTOR_NS
    stamps = base + present.astype(np.int64) * SECTOR_NS
    sample_time = base + np.rint(mean_grid).astype(np.int64)
    first_ns = base + round(float(t_grid.min()))
    last_ns = base + round(float(t_grid.max()))
    sample_time, sample_az, packet = _with_ends(sample_time, sample_az, first_ns, last_ns)
    driver = msg.log_time_ns - (last_ns - stamps)
    samples = PacketSamples(
        vendor=settings.vendor,
        model=settings.model,
        sensor_time_ns=stamps,
        driver_stamp_ns=driver.astype(np.int64),
        sample_time_ns=sample_time,
        sample_azimuth_deg=sample_az % 360.0,
        sample_packet=packet,
        return_modes=frozenset(),
        dual_return=False,
        outlier_blocks=0,
    )
    return CloudSamples(
        samples=samples,
        points=int(t_rel.size),
        first_ns=first_ns,
        last_ns=last_ns,
        stamp_ns=stamp_ns,
        log_time_ns=msg.log_time_ns,
        time_field=time_name,
    )
