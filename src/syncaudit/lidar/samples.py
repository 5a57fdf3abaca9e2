"""Per-packet timing samples: what the revolution tracker and clock estimator consume.

Each packet is reduced to one (time, azimuth) sample, its first block that agrees with
the rest of the packet, plus its sensor time stamp and driver stamp. Linear
interpolation between consecutive packets' samples is exact to far below a nanosecond
for real rotation-rate drift (a 0.5 % sinusoidal drift moves the angle by ~1e-6 deg
from the chord over a 1.3 ms packet), and a block's first-firing time matches its
azimuth on every model (on VLS-128 the later banks reuse the sequence-start azimuth).
The reduction runs where the packets are decoded (worker processes) and shrinks what
crosses to the parent ~10x.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from syncaudit.columns.distinct import distinct
from syncaudit.lidar.packets import PacketTiming

FULL_TURN_DEG = 360.0
MAX_PACKET_SPAN_DEG = 30.0
"""A block further than this from its packet's first block contradicts its own packet."""
SURELY_SANE_DEG = 29.0
"""Blocks this close to their packet's first block pass the MAX_PACKET_SPAN_DEG test
whatever the rounding: packet_samples skips the exact test for such packets."""


@dataclass(frozen=True, slots=True)
class PacketSamples:
    """One chunk of packets reduced for timing: per-packet stamps, one sample each."""

    vendor: str
    model: str
    sensor_time_ns: NDArray[np.int64]
    """(n,) packet time stamps (sensor clock)."""
    driver_stamp_ns: NDArray[np.int64]
    """(n,) driver stamps (checkpoint 242)."""
    sample_time_ns: NDArray[np.int64]
    """(m,) time of each packet's sample, m <= n (packets with no valid block drop out)."""
    sample_azimuth_deg: NDArray[np.float64]
    """(m,) azimuth of each sample."""
    sample_packet: NDArray[np.int64]
    """(m,) index of the packet each sample belongs to."""
    return_modes: frozenset[int]
    dual_return: bool
    outlier_blocks: int
    """Blocks whose azimuth contradicts the rest of their packet (ignored)."""
    declared_rpm_sum: float = 0.0
    """Sum of the packets' own motor-speed fields (RPM), over `declared_rpm_count` packets."""
    declared_rpm_count: int = 0
    """Packets that declare a motor speed (0 for vendors whose packets carry none)."""
    wrap_blocks: int = 0
    """Blocks whose azimuth read 36000 (the wrap), taken as 0."""
    product_id_model: str = ""
    """The model the product byte names where the decoder timed another (PacketTiming)."""
    notes: tuple[str, ...] = ()
    """The decoder's notes (PacketTiming.notes)."""

    @property
    def n_packets(self) -> int:
        """Packets in the chunk."""
        return int(self.sensor_time_ns.shape[0])

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        """Pickle the arrays as one bytes object (what crosses from a reader worker).

        numpy pickles each array apart, with a reconstructor call and a state copy each:
        for the ~40 KB of one scan message's five arrays that cost ~4x the bytes' own
        copy, in the worker and again in the parent. One buffer, unpickled into read-only
        views of its bytes, gives the same dtypes, shapes and values.
        """
        arrays = [np.asarray(getattr(self, name)) for name in _ARRAY_FIELDS]
        layout = tuple((_dtype_code(a.dtype), a.shape) for a in arrays)
        buffer = b"".join(a.tobytes() for a in arrays)
        others = tuple(getattr(self, name) for name in _OTHER_FIELDS)
        return _unpickle_samples, (layout, buffer, others)


_ARRAY_FIELDS = (
    "sensor_time_ns",
    "driver_stamp_ns",
    "sample_time_ns",
    "sample_azimuth_deg",
    "sample_packet",
)
_OTHER_FIELDS = tuple(f.name for f in fields(PacketSamples) if f.name not in _ARRAY_FIELDS)


_CODES: dict[np.dtype[Any], str] = {}
_DTYPES: dict[str, np.dtype[Any]] = {}
"""dtype <-> its `str` ('<i8'), cached: computing either costs more than a view."""


def _dtype_code(dtype: np.dtype[Any]) -> str:
    code = _CODES.get(dtype)
    if code is None:
        code = _CODES[dtype] = dtype.str
    return code


def _unpickle_samples(
    layout: tuple[tuple[str, tuple[int, ...]], ...], buffer: bytes, others: tuple[Any, ...]
) -> PacketSamples:
    """The PacketSamples `PacketSamples.__reduce__` packed: arrays viewing `buffer`."""
    values: dict[str, Any] = dict(zip(_OTHER_FIELDS, others, strict=True))
    offset = 0
    for name, (code, shape) in zip(_ARRAY_FIELDS, layout, strict=True):
        dtype = _DTYPES.get(code)
        if dtype is None:
            dtype = _DTYPES[code] = np.dtype(code)
        count = math.prod(shape)
        array = np.frombuffer(buffer, dtype=dtype, count=count, offset=offset)
        values[name] = array if len(shape) == 1 else array.reshape(shape)
        offset += count * dtype.itemsize
    return PacketSamples(**values)


def packet_samples(timing: PacketTiming, driver_stamp_ns: NDArray[np.int64]) -> PacketSamples:
    """Reduce decoded packets to their first and last trustworthy (time, azimuth) samples.

    Two samples per packet keep the packet a zero crossing falls in exactly what it is
    with every block (a crossing between a packet's first and last block is in it).
    """
    azimuth = timing.block_azimuth_deg
    n = azimuth.shape[0]
    rows = np.arange(n)
    pick, has, outliers = _sample_blocks(azimuth)
    times = timing.block_time_ns[rows[:, None], pick].reshape(-1)
    azimuths = azimuth[rows[:, None], pick].reshape(-1)
    packet = np.repeat(rows, 2)
    keep = np.repeat(has, 2)
    keep[1:] &= np.diff(times) > 0  # one block, or dual-return pairs: the first sample only
    keep[0] &= bool(has[0]) if n else False
    rpm_sum, rpm_count = _declared_rpm(timing.motor_rpm)
    return PacketSamples(
        vendor=timing.vendor,
        model=timing.model,
        sensor_time_ns=timing.sensor_time_ns,
        driver_stamp_ns=np.asarray(driver_stamp_ns, dtype=np.int64),
        sample_time_ns=times[keep],
        sample_azimuth_deg=azimuths[keep],
        sample_packet=packet[keep].astype(np.int64),
        return_modes=_distinct(timing.return_mode),
        dual_return=bool(timing.dual_return.any()),
        outlier_blocks=outliers,
        declared_rpm_sum=rpm_sum,
        declared_rpm_count=rpm_count,
        wrap_blocks=timing.wrap_blocks,
        product_id_model=timing.product_id_model,
        notes=timing.notes,
    )


def _declared_rpm(motor_rpm: NDArray[np.float64] | None) -> tuple[float, int]:
    """Sum and count of the declared motor speeds (finite, positive values only)."""
    if motor_rpm is None or motor_rpm.size == 0:
        return 0.0, 0
    valid = motor_rpm[np.isfinite(motor_rpm) & (motor_rpm > 0)]
    return float(valid.sum()), int(valid.size)


def _sample_blocks(
    azimuth: NDArray[np.float64],
) -> tuple[NDArray[np.intp], NDArray[np.bool_], int]:
    """(n, 2) first and last trustworthy block of each packet, whether it has one, and the
    number of outlier blocks.

    Packets whose blocks all lie near block 0 (nearly all of them) take blocks 0 and b - 1
    without the exact test, whose float remainder is by far the dearest step.
    """
    n, b = azimuth.shape
    if azimuth.size == 0:  # nothing to gain; keep the exact path's behaviour (and errors)
        return _sample_blocks_exact(azimuth)
    pick = np.zeros((n, 2), dtype=np.intp)
    pick[:, 1] = b - 1
    has = np.ones(n, dtype=bool)
    odd = np.flatnonzero(~_near_first_block(azimuth))
    if odd.size == 0:
        return pick, has, 0
    pick[odd], has[odd], outliers = _sample_blocks_exact(azimuth[odd])
    return pick, has, outliers


def _near_first_block(azimuth: NDArray[np.float64]) -> NDArray[np.bool_]:
    """(n,) True where every block is finite and within SURELY_SANE_DEG of block 0, either
    way round the circle: the exact test then finds every block sane, however the float
    remainder rounds (its threshold is a degree further out)."""
    with np.errstate(invalid="ignore"):  # inf - inf: such packets take the exact test
        step = np.abs(azimuth - azimuth[:, :1])
    near = (step < SURELY_SANE_DEG) | (
        (step > FULL_TURN_DEG - SURELY_SANE_DEG) & (step < FULL_TURN_DEG)
    )
    all_near: NDArray[np.bool_] = np.all(near, axis=1)
    return all_near


def _sample_blocks_exact(
    azimuth: NDArray[np.float64],
) -> tuple[NDArray[np.intp], NDArray[np.bool_], int]:
    """_sample_blocks for any packets: the first finite block, and the last block within
    MAX_PACKET_SPAN_DEG of it; blocks further away are outliers."""
    n, b = azimuth.shape
    finite = np.isfinite(azimuth)
    first = np.argmax(finite, axis=1)
    span = (azimuth - azimuth[np.arange(n), first][:, None]) % FULL_TURN_DEG
    sane = finite & ((span < MAX_PACKET_SPAN_DEG) | (span > FULL_TURN_DEG - MAX_PACKET_SPAN_DEG))
    outliers = int(np.sum(finite & ~sane))
    has = sane.any(axis=1)
    last = b - 1 - np.argmax(sane[:, ::-1], axis=1)
    return np.stack([first, last], axis=1), has, outliers


def _distinct(values: NDArray[np.uint8]) -> frozenset[int]:
    """The distinct values, as Python ints (one comparison when they are all the same)."""
    if values.size and (values == values[0]).all():
        return frozenset(values[:1].tolist())
    return frozenset(distinct(values).tolist())


def concat_samples(parts: list[PacketSamples]) -> PacketSamples:
    """One chunk from consecutive ones (LidarScanner gathers them before tracking)."""
    if len(parts) == 1:
        return parts[0]
    offsets = np.cumsum([0] + [p.n_packets for p in parts[:-1]])
    return PacketSamples(
        vendor=parts[-1].vendor,
        model=parts[-1].model,
        sensor_time_ns=np.concatenate([p.sensor_time_ns for p in parts]),
        driver_stamp_ns=np.concatenate([p.driver_stamp_ns for p in parts]),
        sample_time_ns=np.concatenate([p.sample_time_ns for p in parts]),
        sample_azimuth_deg=np.concatenate([p.sample_azimuth_deg for p in parts]),
        sample_packet=np.concatenate(
            [p.sample_packet + o for p, o in zip(parts, offsets, strict=True)]
        ),
        return_modes=frozenset().union(*(p.return_modes for p in parts)),
        dual_return=any(p.dual_return for p in parts),
        outlier_blocks=sum(p.outlier_blocks for p in parts),
        declared_rpm_sum=sum(p.declared_rpm_sum for p in parts),
        declared_rpm_count=sum(p.declared_rpm_count for p in parts),
        wrap_blocks=sum(p.wrap_blocks for p in parts),
        product_id_model=next((p.product_id_model for p in parts if p.product_id_model), ""),
        notes=tuple(dict.fromkeys(n for p in parts for n in p.notes)),
    )
