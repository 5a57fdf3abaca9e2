"""Hesai encoders for the simulator and tests: real-format packets and ROS scan messages.

The inverse of `syncaudit.lidar.hesai`: `encode_hesai` writes point-cloud packets of any
model in `HESAI_LAYOUTS`, `hesai_revolution_schedule` lays out one revolution on the
sensor's firing clock, `build_pandar_scan` / `build_nebula_packets` serialize the ROS
messages the decoder views. Decoders are tested against packets written from the
manuals' tables (tests/lidar/test_hesai_manual.py), not only against this encoder.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from syncaudit.errors import DecodeError
from syncaudit.lidar.hesai import (
    _MODELS,
    _NS_PER_S,
    _RETURNS_OF_MODE,
    HESAI_LAYOUTS,
    PANDAR_PACKET_BYTES,
    HesaiLayout,
    RosHeader,
    _check_encoding,
    _pandar_dtype,
)

__all__ = [
    "HesaiRevolution",
    "build_nebula_packets",
    "build_pandar_scan",
    "encode_hesai",
    "hesai_revolution_schedule",
]


def _header_bytes(header: RosHeader, encoding: str) -> bytes:
    """Serialized std_msgs/Header; CDR output includes the encapsulation header."""
    _check_encoding(encoding)
    sec, nsec = divmod(int(header.stamp_ns), _NS_PER_S)
    name = header.frame_id.encode("utf-8")
    if encoding == "cdr":
        out = b"\x00\x01\x00\x00" + struct.pack("<iII", sec, nsec, len(name) + 1) + name + b"\0"
        return out + b"\0" * (-(len(out) - 4) % 4)
    return struct.pack("<IIII", header.seq, sec, nsec, len(name)) + name


def _split_stamps(stamp_ns: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    stamp = np.asarray(stamp_ns, dtype=np.int64)
    return stamp // _NS_PER_S, stamp % _NS_PER_S


def build_pandar_scan(
    header: RosHeader,
    packet_stamp_ns: NDArray[np.int64],
    data: NDArray[np.uint8],
    size: NDArray[np.uint32],
    encoding: str = "cdr",
) -> bytes:
    """Serialize a `pandar_msgs/msg/PandarScan`; inverse of `pandar_scan_packets`.

    `data` is (n, L) with L <= 1500; bytes past L are written as zeros.
    """
    data = np.asarray(data, dtype=np.uint8)
    n = data.shape[0]
    if data.ndim != 2 or data.shape[1] > PANDAR_PACKET_BYTES:
        raise ValueError("data must be (n, L) with L <= 1500")
    if np.shape(packet_stamp_ns) != (n,) or np.shape(size) != (n,):
        raise ValueError("packet_stamp_ns and size must be (n,)")
    if n and int(np.max(size)) > PANDAR_PACKET_BYTES:
        raise ValueError("size exceeds 1500 bytes")
    rec = np.zeros(n, dtype=_pandar_dtype("<", encoding == "cdr"))
    rec["sec"], rec["nsec"] = _split_stamps(packet_stamp_ns)
    rec["data"][:, : data.shape[1]] = data
    rec["size"] = size
    return _header_bytes(header, encoding) + struct.pack("<I", n) + rec.tobytes()


def build_nebula_packets(
    header: RosHeader,
    packet_stamp_ns: NDArray[np.int64],
    packets: NDArray[np.uint8] | Sequence[NDArray[np.uint8]],
    encoding: str = "cdr",
) -> bytes:
    """Serialize a `nebula_msgs/msg/NebulaPackets`; inverse of `nebula_packets`."""
    n = len(packets)
    if np.shape(packet_stamp_ns) != (n,):
        raise ValueError("packet_stamp_ns must be (n,)")
    sec, nsec = _split_stamps(packet_stamp_ns)
    out = bytearray(_header_bytes(header, encoding))
    out += struct.pack("<I", n)
    cdr = encoding == "cdr"
    for i in range(n):
        if cdr:
            out += b"\0" * (-(len(out) - 4) % 4)
        payload = np.asarray(packets[i], dtype=np.uint8)
        out += struct.pack("<iII" if cdr else "<III", int(sec[i]), int(nsec[i]), payload.size)
        out += payload.tobytes()
    return bytes(out)


def _civil_from_days(
    days: NDArray[np.int64],
) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
    """Inverse of `_days_from_civil`: (year, month, day)."""
    z = days + 719_468
    era = z // 146_097
    doe = z - era * 146_097
    yoe = (doe - doe // 1460 + doe // 36_524 - doe // 146_096) // 365
    doy = doe - (365 * yoe + yoe // 4 - yoe // 100)
    mp = (5 * doy + 2) // 153
    day = doy - (153 * mp + 2) // 5 + 1
    month = np.where(mp < 10, mp + 3, mp - 9)
    return yoe + era * 400 + (month <= 2), month, day


def _layout(model: str) -> HesaiLayout:
    try:
        return HESAI_LAYOUTS[model]
    except KeyError:
        raise DecodeError(f"unknown Hesai model {model!r}; known: {', '.join(_MODELS)}") from None


def encode_hesai(
    model: str,
    block_azimuth_deg: NDArray[np.float64],
    packet_time_ns: NDArray[np.int64],
    return_mode: int = 0x37,
    *,
    distance_m: NDArray[np.float64] | None = None,
    reflectivity: NDArray[np.uint8] | None = None,
    rng: np.random.Generator | None = None,
    motor_rpm: int = 600,
    udp_sequence_start: int = 1,
) -> tuple[NDArray[np.uint8], NDArray[np.uint32]]:
    """Real-format Hesai packets: (data (n, L) uint8, size (n,)).

    Writes header, blocks (azimuth rounded to the packet's resolution, distances in 4 mm,
    reflectivity), tail (return mode, motor speed, date-time, microsecond timestamp, factory
    byte 0x42) and the UDP sequence. Times are floored to the microsecond the packet holds.
    Without `distance_m`, plausible returns are drawn from `rng` (default seed 0);
    in multi-return modes the blocks of one firing repeat the azimuth. CRC fields are zero.
    """
    layout = _layout(model)
    az = np.asarray(block_azimuth_deg, dtype=np.float64)
    t_ns = np.asarray(packet_time_ns, dtype=np.int64)
    n = t_ns.shape[0]
    b, c = layout.n_blocks, layout.n_channels
    if az.shape != (n, b):
        raise ValueError(f"block_azimuth_deg must be ({n}, {b}) for {model}, got {az.shape}")
    n_ret = _RETURNS_OF_MODE.get(return_mode, 0)
    if n_ret == 0 or b % n_ret or (layout.header_bytes != 12 and n_ret > 2):
        raise ValueError(f"return mode {return_mode:#04x} is not supported by {model}")
    if distance_m is None:
        gen = rng if rng is not None else np.random.default_rng(0)
        first = gen.uniform(0.5, 80.0, (n, b // n_ret, 1, c))
        extra = gen.uniform(0.0, 10.0, (n, b // n_ret, n_ret, c)) * (
            gen.random((n, b // n_ret, n_ret, c)) < 0.2
        )
        extra[:, :, 0] = 0.0
        dist = (first + np.cumsum(extra, axis=2)).reshape(n, b, c)
        dist[gen.random((n, b, c)) < 0.05] = 0.0  # no return
        refl = gen.integers(0, 256, (n, b, c), dtype=np.uint8)
    else:
        dist = np.asarray(distance_m, dtype=np.float64)
        refl = (
            np.asarray(reflectivity, dtype=np.uint8)
            if reflectivity is not None
            else np.zeros((n, b, c), dtype=np.uint8)
        )
    if dist.shape != (n, b, c) or refl.shape != (n, b, c):
        raise ValueError(f"distance_m and reflectivity must be ({n}, {b}, {c})")

    tail = layout.body_end + layout.body_trailer_bytes
    if layout.fs_bytes_if_flagged and layout.header_flags & 0x04:
        tail += layout.fs_bytes_if_flagged
    size = tail + layout.tail_bytes + layout.trailer_bytes
    out = np.zeros((n, size), dtype=np.uint8)
    if layout.header_bytes == 12:
        major, minor = layout.protocol or (0, 0)
        lead, flags = (1 if n_ret > 1 else 0), layout.header_flags  # dual: last return leads
        # 0xEEFF, version, reserved 2, lasers, blocks, first-block return, 4 mm, returns, flags
        returns_byte = layout.header_max_returns or n_ret
        out[:, :12] = (0xEE, 0xFF, major, minor, 0, 0, c, b, lead, 4, returns_byte, flags)
    elif layout.header_bytes == 8:
        out[:, :8] = (0xEE, 0xFF, c, b, 0, 4, 0, 0)  # 0xEEFF, lasers, blocks, -, 4 mm, -, -

    body = out[:, layout.header_bytes : layout.body_end].reshape(n, b, layout.block_bytes)
    full_turn = 360 * layout.azimuth_units_per_deg
    raw_az = np.rint(az * layout.azimuth_units_per_deg).astype(np.int64) % full_turn
    a = layout.azimuth_offset
    if layout.model == "Pandar40P":
        body[:, :, 0], body[:, :, 1] = 0xFF, 0xEE
    coarse = raw_az >> 8 if layout.fine_azimuth else raw_az
    body[:, :, a] = coarse & 0xFF
    body[:, :, a + 1] = coarse >> 8
    if layout.fine_azimuth:
        body[:, :, a + 2] = raw_az & 0xFF
    units = body[:, :, layout.block_prefix_bytes :].reshape(n, b, c, layout.unit_bytes)
    raw_d = np.clip(np.rint(dist / 0.004), 0, 0xFFFF).astype(np.int64)
    units[..., 0], units[..., 1], units[..., 2] = raw_d & 0xFF, raw_d >> 8, refl

    seconds, us = t_ns // _NS_PER_S, (t_ns % _NS_PER_S) // 1000
    rows = out[:, tail : tail + layout.tail_bytes]
    rows[:, layout.tail_return_mode] = return_mode
    rows[:, layout.tail_motor_rpm : layout.tail_motor_rpm + 2] = [motor_rpm & 0xFF, motor_rpm >> 8]
    rows[:, layout.tail_timestamp_us : layout.tail_timestamp_us + 4] = _le_bytes(us, 4)
    rows[:, layout.tail_factory] = 0x42
    rows[:, layout.tail_date_time : layout.tail_date_time + 6] = _date_bytes(
        seconds, layout.year_base
    )
    if layout.trailer_bytes:
        seq = udp_sequence_start + np.arange(n, dtype=np.int64)
        out[:, tail + layout.tail_bytes : tail + layout.tail_bytes + 4] = _le_bytes(seq, 4)
    return out, np.full(n, size, dtype=np.uint32)


def _le_bytes(values: NDArray[np.int64], count: int) -> NDArray[np.uint8]:
    """(n, count) little-endian bytes of non-negative integers."""
    shifts = 8 * np.arange(count, dtype=np.int64)
    return ((values[:, None] >> shifts) & 0xFF).astype(np.uint8)


def _date_bytes(seconds: NDArray[np.int64], year_base: int) -> NDArray[np.uint8]:
    """(n, 6) date field: calendar with a year offset, or 0 + 5-byte big-endian Unix seconds."""
    if year_base == 0:
        out = np.zeros((seconds.shape[0], 6), dtype=np.uint8)
        out[:, 1:] = _le_bytes(seconds, 5)[:, ::-1]
        return out
    days, rest = seconds // 86_400, seconds % 86_400
    year, month, day = _civil_from_days(days)
    year_byte = year - year_base
    if ((year_byte < 0) | (year_byte > 255) | ((year_base == 1900) & (year_byte < 100))).any():
        raise ValueError(
            f"packet times outside the years the date field can hold (base {year_base})"
        )
    cols = (year_byte, month, day, rest // 3600, rest % 3600 // 60, rest % 60)
    return np.stack(cols, axis=1).astype(np.uint8)


@dataclass(frozen=True, slots=True)
class HesaiRevolution:
    """One revolution of packets laid out on the sensor's firing clock."""

    model: str
    return_mode: int
    block_azimuth_deg: NDArray[np.float64]
    """(n, B) azimuth of each block, on the packet's azimuth grid."""
    packet_time_ns: NDArray[np.int64]
    """(n,) packet time t0, whole microseconds."""
    block_time_ns: NDArray[np.int64]
    """(n, B) first-firing time of each block, as `decode_hesai` computes it."""


def hesai_revolution_schedule(
    model: str,
    rpm: float,
    start_time_ns: int,
    *,
    return_mode: int = 0x37,
    start_azimuth_deg: float = 0.0,
) -> HesaiRevolution:
    """Packets of one revolution starting at `start_time_ns` and `start_azimuth_deg`.

    Firing rounds follow the model's fixed round period (e.g. 55.56 us Pandar40P, 50 us XT),
    so the azimuth step per round is rpm * 6 deg/s * period; the packet count is the rounds of
    one turn divided by rounds per packet (rounded up). Packet times are floored to whole
    microseconds and block times derived from them by the decoder's rule; azimuths follow
    the block times exactly (constant angular velocity), rounded to the packet's resolution.
    """
    layout = _layout(model)
    n_ret = _RETURNS_OF_MODE.get(return_mode, 0)
    if n_ret == 0 or layout.n_blocks % n_ret:
        raise ValueError(f"return mode {return_mode:#04x} is not supported by {model}")
    if not rpm > 0:
        raise ValueError("rpm must be positive")
    deg_per_ns = rpm * 360.0 / 60e9
    rounds_per_turn = round(360.0 / (deg_per_ns * layout.round_period_ns))
    per_packet = layout.n_blocks // n_ret
    n = -(-rounds_per_turn // per_packet)
    first_round = np.arange(n, dtype=np.int64) * per_packet
    first_start = start_time_ns + (layout.period_num_ns * first_round) // layout.period_den
    returns = np.full(n, n_ret, dtype=np.int64)
    offsets = layout.block_offset_ns(returns)
    packet_ns = (first_start - offsets[:, 0]) // 1000 * 1000
    block_ns = packet_ns[:, None] + offsets
    azimuth = (start_azimuth_deg + deg_per_ns * (block_ns - start_time_ns)) % 360.0
    units = layout.azimuth_units_per_deg
    azimuth = (np.rint(azimuth * units) % (360 * units)) / units
    return HesaiRevolution(model, return_mode, azimuth, packet_ns, block_ns)
