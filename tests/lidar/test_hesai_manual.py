"""Hesai packets written byte by byte from the user manuals' tables, not by our encoder.

PandarXT32M2X user manual, section 3.1.2 (all multi-byte values little endian):
pre-header 0xEE 0xFF, protocol 6.1, 2 reserved; header: Laser Num 0x20, Block Num 0x06,
First Block Return, Dis Unit 0x04, Return Number, Flags (bit 0: UDP sequence); body: 6 blocks
of Azimuth (uint16, 0.01 deg) + 32 x (Distance uint16, Reflectivity, Reserved); tail:
Reserved 10, Return Mode, Motor Speed (uint16 RPM), Date & Time (year - 1900, month, day,
hour, minute, second), Timestamp (uint32 us), Factory Information; UDP sequence (uint32).
Appendix B: one firing round every 50 us; in an r-return mode one round fills r adjacent
blocks with the same azimuth and start time; the packet time t0 is the trigger of the round
in the last block(s); a block starts 5.632 us after its round's trigger.

The header's Return Number is what the sensor can produce at most (the PandarXT manual:
"0x02, each channel can generate two returns maximum"); a real XT32M capture holds 3 there
in its dual mode 0x3C, which made the decoder group 6 blocks as 2 x 3 (1132 RPM, 168
packets/rev, 852 drops where the sensor turned at 600 RPM).
"""

from __future__ import annotations

import struct
from datetime import UTC, datetime

import numpy as np
import pytest
from numpy.typing import NDArray

from syncaudit.columns.lidar import LidarScan
from syncaudit.lidar.hesai import decode_hesai, hesai_returns
from syncaudit.lidar.samples import packet_samples
from syncaudit.lidar.scan import LidarScanner

ROUND_NS = 50_000
BLOCK_START_AFTER_TRIGGER_NS = 5_632
START = datetime(2024, 5, 1, 12, 0, 0, tzinfo=UTC)
START_NS = int(START.timestamp()) * 1_000_000_000
FIRST_AZIMUTH = 12_345  # 0.01 deg


def _xt32m_packet(
    rounds: list[tuple[int, int]],
    return_mode: int,
    t0_ns: int,
    *,
    header_returns: int = 3,
    motor_rpm: int = 600,
    sequence: int = 1,
) -> bytes:
    """One 820-byte XT32M2X packet; `rounds` lists (azimuth, distance) per firing round."""
    r = len(rounds) and 6 // len(rounds)
    out = bytearray(b"\xee\xff\x06\x01\x00\x00")  # pre-header
    out += bytes([0x20, 0x06, 0x00, 0x04, header_returns, 0x01])  # header
    for azimuth, distance in rounds:
        for ret in range(r):  # the round's returns in adjacent blocks, same azimuth
            out += struct.pack("<H", azimuth)
            unit = struct.pack("<HBB", distance + 25 * ret, 100, 0)
            out += unit * 32
    seconds, ns = divmod(t0_ns, 1_000_000_000)
    t = datetime.fromtimestamp(seconds, tz=UTC)
    out += bytes(10) + bytes([return_mode]) + struct.pack("<H", motor_rpm)
    out += bytes([t.year - 1900, t.month, t.day, t.hour, t.minute, t.second])
    out += struct.pack("<I", ns // 1000) + b"\x42"
    out += struct.pack("<I", sequence)
    assert len(out) == 820
    return bytes(out)


def _xt32m_capture(
    return_mode: int, returns: int, turns: float, rpm: float = 600.0, **kw: int
) -> tuple[NDArray[np.uint8], NDArray[np.uint32], NDArray[np.int64], NDArray[np.int64]]:
    """Packets of `turns` revolutions: (data, size, host stamps, true block start times)."""
    per_packet = 6 // returns
    step = round(rpm * 6 * ROUND_NS / 1e9 * 100)  # azimuth units per round: 18 at 600 RPM
    n = int(turns * 36_000 / (step * per_packet))
    packets, truth = [], []
    for p in range(n):
        first = p * per_packet
        rounds = [((FIRST_AZIMUTH + step * (first + k)) % 36_000, 2_500) for k in range(per_packet)]
        starts = [
            START_NS + BLOCK_START_AFTER_TRIGGER_NS + ROUND_NS * (first + k)
            for k in range(per_packet)
        ]
        t0 = starts[-1] - BLOCK_START_AFTER_TRIGGER_NS
        packets.append(_xt32m_packet(rounds, return_mode, t0, sequence=p + 1, **kw))
        truth.append(np.repeat(starts, returns))
    data = np.frombuffer(b"".join(packets), dtype=np.uint8).reshape(n, 820)
    size = np.full(n, 820, dtype=np.uint32)
    host = START_NS + 1_000_000 + ROUND_NS * per_packet * np.arange(n, dtype=np.int64)
    return data, size, host, np.array(truth, dtype=np.int64)


def _scan(data: NDArray[np.uint8], size: NDArray[np.uint32], host: NDArray[np.int64]) -> LidarScan:
    """Decode in scan-sized chunks and reduce as `info`/`audit` do."""
    scanner = LidarScanner.create("/pandar_packets")
    for lo in range(0, data.shape[0], 300):
        timing = decode_hesai(data[lo : lo + 300], size[lo : lo + 300], host[lo : lo + 300])
        scanner.feed(packet_samples(timing, host[lo : lo + 300]))
    return scanner.finish()


@pytest.mark.parametrize(
    ("return_mode", "returns", "per_rev"),
    [
        (0x3C, 2, 666.67),  # dual first + strongest, as on the real capture
        (0x39, 2, 666.67),  # dual last + strongest
        (0x3B, 2, 666.67),  # dual last + first
        (0x3D, 3, 1000.0),  # triple first + last + strongest
        (0x37, 1, 333.33),  # single strongest
    ],
)
def test_xt32m_manual_packets(return_mode: int, returns: int, per_rev: float) -> None:
    data, size, host, truth = _xt32m_capture(return_mode, returns, turns=3.2)
    timing = decode_hesai(data, size, host)
    assert timing.model == "PandarXT32M"
    np.testing.assert_array_equal(timing.block_time_ns, truth)  # Appendix B, to the ns
    assert bool(timing.dual_return.all()) == (returns >= 2)
    scan = _scan(data, size, host)
    assert scan.rpm == pytest.approx(600.0, rel=1e-4)
    assert scan.packets_per_revolution == pytest.approx(per_rev, abs=1)
    assert scan.dropped_packets == 0
    assert scan.declared_rpm == 600.0
    assert scan.warnings == []


def test_header_return_number_does_not_group_blocks() -> None:
    """Whatever the header's Return Number holds, the tail's mode decides the grouping."""
    for header_returns in (1, 2, 3):
        data, size, host, truth = _xt32m_capture(0x3C, 2, 1.2, header_returns=header_returns)
        np.testing.assert_array_equal(decode_hesai(data, size, host).block_time_ns, truth)


def test_unknown_return_mode_grouped_by_azimuth() -> None:
    """A mode code the tables do not list: the blocks sharing an azimuth form one firing."""
    data, size, host, truth = _xt32m_capture(0x3C, 2, 1.2)
    data = data.copy()
    data[:, 12 + 6 * 130 + 10] = 0x45
    np.testing.assert_array_equal(decode_hesai(data, size, host).block_time_ns, truth)


def test_motor_speed_disagreement_warns() -> None:
    """A sensor declaring 1200 RPM that turns at 600 RPM (or a wrong decode) is reported."""
    data, size, host, _ = _xt32m_capture(0x3C, 2, 2.2, motor_rpm=1200)
    scan = _scan(data, size, host)
    assert scan.declared_rpm == 1200.0
    assert scan.rpm_disagreement == pytest.approx(-0.5, abs=1e-3)
    (warning,) = scan.warnings
    assert "600.00 RPM" in warning and "1200 RPM" in warning and "-50.0%" in warning


# ----------------------------------------------------------------------------- OT128
# OT128 (Pandar128E4X) user manual, section 3.1.2, protocol 1.4: pre-header 0xEE 0xFF
# 0x01 0x04 + 2 reserved; header Laser Num 0x80, Block Num 0x02, First Block Return,
# Dis Unit 0x04, Return Number, Flags ([4] confidence, [3] digital signature, [2]
# functional safety, [1] IMU, [0] UDP sequence); body 2 x (Azimuth uint16 0.01 deg +
# 128 x (Distance uint16, Reflectivity)) + CRC 4; functional safety 17; tail: Reserved 9,
# Azimuth State 2, Operational State, Return Mode, Motor Speed uint16, Date & Time (year -
# 1900), Timestamp uint32 us, Factory Information; UDP Sequence 4, IMU 22, CRC 4: 861
# bytes (the manual's revision O01-en-230920: "point cloud UDP data from 893 to 861",
# the 893 including the 32-byte signature). Block timing as tier4/nebula's Pandar128E4X:
# a round every 55.556 us, block start = t0 + 43.346 us + 2.378 us (earliest channel);
# single return: block 1 one round before block 2; dual: both blocks one round.
OT128_ROUND_NS = 55_556
OT128_START_AFTER_T0_NS = 43_346 + 2_378


def _ot128_packet(
    azimuths: tuple[int, int], return_mode: int, t0_ns: int, *, flags: int = 0x07, seq: int = 1
) -> bytes:
    """One OT128 packet; 4-byte channel units (with confidence) when flag bit 4 is set."""
    returns = 2 if return_mode in (0x39, 0x3B, 0x3C) else 1
    out = bytearray(b"\xee\xff\x01\x04\x00\x00")
    out += bytes([0x80, 0x02, 0x01 if returns == 2 else 0x00, 0x04, returns, flags])
    for block, azimuth in enumerate(azimuths):
        out += struct.pack("<H", azimuth)
        unit = struct.pack("<HB", 1_000 + 10 * block, 50)
        if flags & 0x10:
            unit += b"\x03"  # confidence
        out += unit * 128
    out += struct.pack("<I", 0)  # body CRC (not checked)
    if flags & 0x04:
        out += bytes(17)  # functional safety
    seconds, ns = divmod(t0_ns, 1_000_000_000)
    t = datetime.fromtimestamp(seconds, tz=UTC)
    out += bytes(9) + struct.pack("<H", 0) + bytes([1, return_mode]) + struct.pack("<H", 600)
    out += bytes([t.year - 1900, t.month, t.day, t.hour, t.minute, t.second])
    out += struct.pack("<I", ns // 1000) + b"\x42"
    if flags & 0x01:
        out += struct.pack("<I", seq)
    if flags & 0x02:
        out += bytes(22)  # IMU
    out += struct.pack("<I", 0)  # tail CRC
    if flags & 0x08:
        out += bytes(32)  # digital signature
    return bytes(out)


def _ot128_capture(
    return_mode: int, turns: float, flags: int = 0x07
) -> tuple[NDArray[np.uint8], NDArray[np.uint32], NDArray[np.int64], NDArray[np.int64]]:
    returns = 2 if return_mode in (0x39, 0x3B, 0x3C) else 1
    rounds = 2 // returns
    step = round(600 * 6 * OT128_ROUND_NS / 1e9 * 100)  # azimuth units per round: 20
    n = int(turns * 36_000 / (step * rounds))
    packets, truth, t0s = [], [], []
    base = START_NS + 1_000_000  # t0 on whole microseconds
    for p in range(n):
        first = p * rounds
        t0 = base + (first + rounds - 1) * OT128_ROUND_NS // 1000 * 1000
        starts = [
            t0 + OT128_START_AFTER_T0_NS - OT128_ROUND_NS * (rounds - 1 - k) for k in range(rounds)
        ]
        az = [(FIRST_AZIMUTH + step * (first + k)) % 36_000 for k in range(rounds)]
        if returns == 2:
            az, starts = az * 2, starts * 2
        packets.append(_ot128_packet((az[0], az[1]), return_mode, t0, flags=flags, seq=p))
        truth.append(starts)
        t0s.append(t0)
    size = len(packets[0])
    data = np.frombuffer(b"".join(packets), dtype=np.uint8).reshape(n, size)
    host = np.array(t0s, dtype=np.int64) + 700_000
    return data, np.full(n, size, dtype=np.uint32), host, np.array(truth, dtype=np.int64)


@pytest.mark.parametrize(
    ("return_mode", "flags", "size", "per_rev"),
    [
        (0x37, 0x07, 861, 900.0),  # single strongest, UDP sequence + IMU + functional safety
        (0x39, 0x07, 861, 1800.0),  # dual last + strongest
        (0x37, 0x0F, 893, 900.0),  # with the 32-byte digital signature
        (0x3B, 0x11, 1078, 1800.0),  # confidence byte in every unit, no FS/IMU
    ],
)
def test_ot128_manual_packets(return_mode: int, flags: int, size: int, per_rev: float) -> None:
    data, sizes, host, truth = _ot128_capture(return_mode, 3.2, flags)
    assert data.shape[1] == size
    timing = decode_hesai(data, sizes, host)
    assert timing.model == "Pandar128E4X"
    np.testing.assert_array_equal(timing.block_time_ns, truth)
    np.testing.assert_array_equal(timing.sensor_time_ns, host - 700_000)
    scan = _scan(data, sizes, host)
    assert scan.rpm == pytest.approx(600.0, rel=2e-3)
    assert scan.packets_per_revolution == pytest.approx(per_rev, abs=1)
    assert scan.dropped_packets == 0
    assert scan.warnings == []
    distance_m, _ = hesai_returns(data[:2], sizes[:2])
    assert distance_m[0, 0, 0] == pytest.approx(4.0) and distance_m[0, 1, 5] == pytest.approx(4.04)
