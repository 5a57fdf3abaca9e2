"""Hesai LiDAR: zero-copy ROS packet-message views and packet timing decode.

Two layers, all vectorised over packets (the encoders live in `hesai_encode`):

1. ROS messages. `pandar_msgs/msg/PandarScan` (fixed 1500-byte packet buffers) is viewed
   as numpy strided arrays straight over the serialized bytes; `nebula_msgs/msg/NebulaPackets`
   (variable-length packets) is walked once. Both have exact inverses
   (`hesai_encode.build_*`).
2. Packets. `decode_hesai` detects the model from the bytes and returns `PacketTiming`:
   the packet's sensor time (date-time + microseconds in the tail), each block's azimuth and
   the time of the block's first firing from the user manuals' block timing rules.

Byte layouts follow the Hesai user manuals and the packet formats of tier4/nebula and
HesaiLidar_SDK_2.0 (read, not copied). Units: azimuths in degrees, times in int64 ns.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Final, NamedTuple

import numpy as np
from numpy.typing import NDArray

from syncaudit.columns.distinct import distinct
from syncaudit.errors import DecodeError
from syncaudit.lidar.packets import PacketTiming
from syncaudit.logs.wire import cdr_byte_order, cdr_header, ros1_header

__all__ = [
    "HESAI_LAYOUTS",
    "PANDAR_PACKET_BYTES",
    "HesaiLayout",
    "RosHeader",
    "decode_hesai",
    "detect_hesai_model",
    "hesai_returns",
    "nebula_packets",
    "pandar_scan_packets",
    "returns_per_firing",
    "ros_header",
    "stack_packets",
]

PANDAR_PACKET_BYTES: Final = 1500
"""Size of `pandar_msgs/PandarPacket.data` (uint8[1500])."""

_NS_PER_S: Final = 1_000_000_000
_PANDAR_ELEMENT_BYTES: Final = 4 + 4 + PANDAR_PACKET_BYTES + 4  # stamp, data, size
_ENCODINGS: Final = ("cdr", "ros1")

Bytes = bytes | bytearray | memoryview | NDArray[np.uint8]

# ============================================================================ ROS messages


class RosHeader(NamedTuple):
    """`std_msgs/Header` of a message: stamp, frame id and (ROS 1 only) sequence number."""

    stamp_ns: int
    frame_id: str
    seq: int = 0


def _u8(raw: Bytes) -> NDArray[np.uint8]:
    """Raw message bytes as a 1-D uint8 array without copying."""
    if isinstance(raw, np.ndarray):
        if raw.dtype != np.uint8 or raw.ndim != 1:
            raise DecodeError("message bytes must be a 1-D uint8 array")
        return raw
    return np.frombuffer(raw, dtype=np.uint8)


def _check_encoding(encoding: str) -> None:
    if encoding not in _ENCODINGS:
        raise ValueError(f"encoding must be one of {_ENCODINGS}, not {encoding!r}")


class _Cursor:
    """Reads a serialized ROS message: CDR (CDR_LE/CDR_BE, aligned) or ROS 1 (packed).

    The encapsulation and the header are read by `syncaudit.logs.wire`.
    """

    def __init__(self, buf: NDArray[np.uint8], encoding: str) -> None:
        _check_encoding(encoding)
        self.buf = buf
        self.mem = buf.data
        self.cdr = encoding == "cdr"
        self.endian = cdr_byte_order(self.mem) if self.cdr else "<"
        self.pos = 4 if self.cdr else 0

    def align(self, n: int) -> None:
        """Skip CDR padding so that the next read is n-aligned (counted after byte 4).

        `wire.cdr_align` inlined: NebulaPackets aligns twice a packet.
        """
        if self.cdr:
            self.pos += -(self.pos - 4) % n

    def need(self, n: int, what: str) -> None:
        if self.pos + n > self.buf.size:
            raise DecodeError(
                f"message truncated reading {what}: needs {self.pos + n} bytes, has {self.buf.size}"
            )

    def u32(self, what: str) -> int:
        self.align(4)
        self.need(4, what)
        (v,) = struct.unpack_from(self.endian + "I", self.mem, self.pos)
        self.pos += 4
        return int(v)

    def time_ns(self, what: str) -> int:
        """builtin_interfaces/Time (int32 sec) in CDR, `time` (uint32 sec) in ROS 1."""
        self.align(4)
        self.need(8, what)
        fmt = self.endian + ("iI" if self.cdr else "II")
        sec, nsec = struct.unpack_from(fmt, self.mem, self.pos)
        if nsec >= _NS_PER_S:
            raise DecodeError(f"{what}: nanoseconds field {nsec} is not below 1e9")
        self.pos += 8
        return int(sec) * _NS_PER_S + int(nsec)

    def header(self) -> RosHeader:
        seq = 0
        if self.cdr:
            sec, nsec, frame_id, self.pos = cdr_header(self.mem, self.pos, self.endian)
        else:
            seq, sec, nsec, frame_id, self.pos = ros1_header(self.mem, self.pos)
        if nsec >= _NS_PER_S:
            raise DecodeError(f"header.stamp: nanoseconds field {nsec} is not below 1e9")
        return RosHeader(int(sec) * _NS_PER_S + int(nsec), frame_id, seq)


def ros_header(raw: Bytes, encoding: str = "cdr") -> RosHeader:
    """The leading `std_msgs/Header` of a serialized message (PandarScan, NebulaPackets...)."""
    return _Cursor(_u8(raw), encoding).header()


def _pandar_dtype(endian: str, cdr: bool) -> np.dtype[np.void]:
    """One serialized PandarPacket: 1512 bytes in both encodings (1508 is already 4-aligned)."""
    return np.dtype(
        [
            ("sec", endian + ("i4" if cdr else "u4")),
            ("nsec", endian + "u4"),
            ("data", "u1", (PANDAR_PACKET_BYTES,)),
            ("size", endian + "u4"),
        ]
    )


def pandar_scan_packets(
    raw: Bytes, encoding: str = "cdr"
) -> tuple[NDArray[np.int64], NDArray[np.uint8], NDArray[np.uint32]]:
    """View one serialized `pandar_msgs/msg/PandarScan` as packet columns, without copying data.

    Returns the per-packet driver stamps (n,) int64 ns, the packet buffers (n, 1500) uint8 as a
    strided view into `raw`, and the payload lengths (n,). `encoding` is "cdr" (ROS 2 XCDR1,
    4-byte encapsulation header, alignment relative to after it) or "ros1" (packed).
    """
    cur = _Cursor(_u8(raw), encoding)
    cur.header()
    n = cur.u32("packets length")
    cur.align(4)
    end = cur.pos + n * _PANDAR_ELEMENT_BYTES
    if end > cur.buf.size:
        raise DecodeError(
            f"PandarScan declares {n} packets ({end} bytes) but the message has {cur.buf.size}"
        )
    if cur.buf.size - end > 3:
        raise DecodeError(f"PandarScan has {cur.buf.size - end} unexplained trailing bytes")
    rec = cur.buf[cur.pos : end].view(_pandar_dtype(cur.endian, cur.cdr))
    nsec = rec["nsec"]
    if n and int(nsec.max()) >= _NS_PER_S:
        raise DecodeError("PandarPacket stamp has a nanoseconds field not below 1e9")
    stamp_ns = rec["sec"].astype(np.int64) * _NS_PER_S + nsec.astype(np.int64)
    size = rec["size"]
    if cur.endian == ">":
        size = size.astype(np.uint32)  # native byte order for callers
    if n and int(size.max()) > PANDAR_PACKET_BYTES:
        raise DecodeError(f"PandarPacket.size {int(size.max())} exceeds the 1500-byte buffer")
    data: NDArray[np.uint8] = rec["data"]
    return stamp_ns, data, size


def nebula_packets(
    raw: Bytes, encoding: str = "cdr"
) -> tuple[NDArray[np.int64], NDArray[np.uint8] | list[NDArray[np.uint8]]]:
    """View one serialized `nebula_msgs/msg/NebulaPackets`: stamps (n,) ns and the packets.

    The packets come back as one zero-copy (n, L) strided view when all have the same length
    (the usual case: one sensor, one packet size), else as a list of zero-copy 1-D views.
    `stack_packets` turns either form into the (data, size) pair `decode_hesai` takes.
    """
    cur = _Cursor(_u8(raw), encoding)
    cur.header()
    n = cur.u32("packets length")
    stamp_ns = np.empty(n, dtype=np.int64)
    offset = np.empty(n, dtype=np.int64)
    length = np.empty(n, dtype=np.int64)
    for i in range(n):
        stamp_ns[i] = cur.time_ns(f"packet {i} stamp")
        length[i] = cur.u32(f"packet {i} data length")
        cur.need(int(length[i]), f"packet {i} data")
        offset[i] = cur.pos
        cur.pos += int(length[i])
    if cur.buf.size - cur.pos > 3:
        raise DecodeError(f"NebulaPackets has {cur.buf.size - cur.pos} unexplained trailing bytes")
    buf = cur.buf
    if n == 0:
        return stamp_ns, np.empty((0, 0), dtype=np.uint8)
    step = np.diff(offset)
    if (length == length[0]).all() and (n == 1 or (step == step[0]).all()):
        first = int(offset[0])
        stride = int(step[0]) if n > 1 else int(length[0])
        view = np.lib.stride_tricks.as_strided(
            buf[first:], shape=(n, int(length[0])), strides=(stride, 1), writeable=False
        )
        return stamp_ns, view
    return stamp_ns, [
        buf[o : o + ln] for o, ln in zip(offset.tolist(), length.tolist(), strict=True)
    ]


def stack_packets(
    packets: NDArray[np.uint8] | Sequence[NDArray[np.uint8]],
) -> tuple[NDArray[np.uint8], NDArray[np.uint32]]:
    """Packets (an (n, L) array or a list of 1-D arrays) as (data (n, Lmax), size (n,))."""
    if isinstance(packets, np.ndarray):
        if packets.ndim != 2:
            raise DecodeError("packets array must be 2-D (n, L)")
        return packets, np.full(packets.shape[0], packets.shape[1], dtype=np.uint32)
    size = np.array([p.shape[0] for p in packets], dtype=np.uint32)
    data = np.zeros((len(packets), int(size.max()) if len(packets) else 0), dtype=np.uint8)
    for i, p in enumerate(packets):
        data[i, : p.shape[0]] = p
    return data, size


# ============================================================================ packet layouts


@dataclass(frozen=True, slots=True)
class HesaiLayout:
    """Byte layout and block timing of one Hesai model's point-cloud packet.

    Offsets are bytes from the packet start (blocks) or from the tail start (tail fields).
    Block timing: the time of a block's first firing is the packet time t0 plus
    `anchor_ns + sign * floor(period_num_ns * m / period_den)`, where m counts firing rounds
    after the block (`anchored_last`, sign -1) or before it (sign +1) in the packet.
    """

    model: str
    protocol: tuple[int, int] | None
    """Pre-header protocol version (major, minor); None for Pandar40P/64 (no version)."""
    header_bytes: int
    n_blocks: int
    n_channels: int
    block_prefix_bytes: int
    """Bytes before the channel units in a block (flag, azimuth, fine azimuth)."""
    azimuth_offset: int
    """Offset of the uint16 azimuth within a block."""
    fine_azimuth: bool
    """AT128: a uint8 of 1/256 azimuth units follows the uint16 azimuth."""
    unit_bytes: int
    body_trailer_bytes: int
    """Bytes between the last block and the tail (body CRC)."""
    fs_bytes_if_flagged: int
    """Functional-safety section before the tail when header flag bit 2 is set (QT128)."""
    tail_bytes: int
    tail_return_mode: int
    tail_motor_rpm: int
    tail_date_time: int
    tail_timestamp_us: int
    tail_factory: int
    tail_mode_flag: int | None
    trailer_bytes: int
    """Bytes the encoder writes after the tail (UDP sequence, tail CRC)."""
    header_flags: int
    """Header flags byte the encoder writes (bit 0 UDP sequence, bit 2 functional safety)."""
    year_base: int
    """Year byte offset the sensor writes: 2000 (Pandar40P/64) or 1900; 0 = Unix seconds."""
    azimuth_units_per_deg: int
    anchor_ns: int
    period_num_ns: int
    period_den: int
    anchored_last: bool
    valid_sizes: tuple[int, ...] = ()
    """Exact packet sizes accepted when the model has no self-describing header."""
    unit_bytes_if_confidence: int = 0
    """Protocol 1.4: channel unit size when header flag bit 4 (confidence) is set."""
    header_max_returns: int = 0
    """What the sensor writes in the 12-byte header's Return Number byte when it is the
    model's maximum rather than the current mode (PandarXT: 2, XT32M2X: 3); 0: the mode's."""

    @property
    def block_bytes(self) -> int:
        """Size of one block."""
        return self.block_prefix_bytes + self.n_channels * self.unit_bytes

    @property
    def body_end(self) -> int:
        """Offset just past the last block."""
        return self.header_bytes + self.n_blocks * self.block_bytes

    @property
    def round_period_ns(self) -> float:
        """Time between firing rounds, ns."""
        return self.period_num_ns / self.period_den

    def block_offset_ns(self, n_returns: NDArray[np.int64]) -> NDArray[np.int64]:
        """(n, B) offset of each block's first firing from the packet time, ns."""
        r = np.asarray(n_returns, dtype=np.int64)[:, None]
        block = np.arange(self.n_blocks, dtype=np.int64)[None, :]
        rounds = self.n_blocks // r
        k = block // r
        if self.anchored_last:
            m = rounds - 1 - k
            return self.anchor_ns - (self.period_num_ns * m) // self.period_den
        return self.anchor_ns + (self.period_num_ns * k) // self.period_den


def _general(
    model: str,
    protocol: tuple[int, int],
    n_blocks: int,
    n_channels: int,
    tail: dict[str, int],
    **kw: int | bool,
) -> HesaiLayout:
    """Layout of a model using the 12-byte 'general' header (0xEE 0xFF + version)."""
    layout = HesaiLayout(
        model=model,
        protocol=protocol,
        header_bytes=12,
        n_blocks=n_blocks,
        n_channels=n_channels,
        block_prefix_bytes=int(kw.pop("block_prefix_bytes", 2)),
        azimuth_offset=0,
        fine_azimuth=bool(kw.pop("fine_azimuth", False)),
        unit_bytes=int(kw.pop("unit_bytes", 4)),
        body_trailer_bytes=int(kw.pop("body_trailer_bytes", 0)),
        fs_bytes_if_flagged=int(kw.pop("fs_bytes_if_flagged", 0)),
        unit_bytes_if_confidence=int(kw.pop("unit_bytes_if_confidence", 0)),
        header_max_returns=int(kw.pop("header_max_returns", 0)),
        tail_bytes=tail["len"],
        tail_return_mode=tail["return_mode"],
        tail_motor_rpm=tail["motor"],
        tail_date_time=tail["date"],
        tail_timestamp_us=tail["us"],
        tail_factory=tail["factory"],
        tail_mode_flag=tail.get("mode_flag"),
        trailer_bytes=int(kw.pop("trailer_bytes", 4)),
        header_flags=int(kw.pop("header_flags", 0x01)),
        year_base=int(kw.pop("year_base", 1900)),
        azimuth_units_per_deg=int(kw.pop("azimuth_units_per_deg", 100)),
        anchor_ns=int(kw.pop("anchor_ns")),
        period_num_ns=int(kw.pop("period_num_ns")),
        period_den=int(kw.pop("period_den", 1)),
        anchored_last=bool(kw.pop("anchored_last", True)),
    )
    if kw:
        raise TypeError(f"unknown layout fields {sorted(kw)}")
    return layout


# Tail of Pandar40P and Pandar64: reserved 5, shutdown 1, reserved 2, motor, us, mode,
# factory, date.
_TAIL_40P: Final = {"len": 22, "motor": 8, "us": 10, "return_mode": 14, "factory": 15, "date": 16}
# PandarXT16/32/32M (protocol 6.1): reserved 9, shutdown 1, mode, motor, date, us, factory.
_TAIL_XT: Final = {"len": 24, "return_mode": 10, "motor": 11, "date": 13, "us": 19, "factory": 23}

HESAI_LAYOUTS: Final[dict[str, HesaiLayout]] = {
    # 10 blocks of 0xFFEE + azimuth + 40 x 3 B; manual: block end = t0 - 28.58 us
    # - 55.56 us per later round; first laser fires 54.67 us before the block end.
    "Pandar40P": HesaiLayout(
        model="Pandar40P",
        protocol=None,
        header_bytes=0,
        n_blocks=10,
        n_channels=40,
        block_prefix_bytes=4,
        azimuth_offset=2,
        fine_azimuth=False,
        unit_bytes=3,
        body_trailer_bytes=0,
        fs_bytes_if_flagged=0,
        tail_bytes=_TAIL_40P["len"],
        tail_return_mode=_TAIL_40P["return_mode"],
        tail_motor_rpm=_TAIL_40P["motor"],
        tail_date_time=_TAIL_40P["date"],
        tail_timestamp_us=_TAIL_40P["us"],
        tail_factory=_TAIL_40P["factory"],
        tail_mode_flag=None,
        trailer_bytes=0,
        header_flags=0,
        year_base=2000,
        azimuth_units_per_deg=100,
        anchor_ns=-(28_580 + 54_670),
        period_num_ns=55_560,
        period_den=1,
        anchored_last=True,
        valid_sizes=(1262, 1266),
    ),
    # 8-byte header (0xEEFF, lasers, blocks, reserved, dis unit, reserved 2); block end =
    # t0 - 42.58 us - 55.56 us per later round; first laser fires 54.668 us before the end.
    "Pandar64": HesaiLayout(
        model="Pandar64",
        protocol=None,
        header_bytes=8,
        n_blocks=6,
        n_channels=64,
        block_prefix_bytes=2,
        azimuth_offset=0,
        fine_azimuth=False,
        unit_bytes=3,
        body_trailer_bytes=0,
        fs_bytes_if_flagged=0,
        tail_bytes=_TAIL_40P["len"],
        tail_return_mode=_TAIL_40P["return_mode"],
        tail_motor_rpm=_TAIL_40P["motor"],
        tail_date_time=_TAIL_40P["date"],
        tail_timestamp_us=_TAIL_40P["us"],
        tail_factory=_TAIL_40P["factory"],
        tail_mode_flag=None,
        trailer_bytes=0,
        header_flags=0,
        year_base=2000,
        azimuth_units_per_deg=100,
        anchor_ns=-(42_580 + 54_668),
        period_num_ns=55_560,
        period_den=1,
        anchored_last=True,
        valid_sizes=(1194, 1198),
    ),
    # Protocol 3.1; block start = t0 + 25.71 us + 166.67 us per earlier round.
    "PandarQT64": _general(
        "PandarQT64",
        (3, 1),
        4,
        64,
        {"len": 24, "motor": 10, "us": 12, "return_mode": 16, "factory": 17, "date": 18},
        anchor_ns=25_710,
        period_num_ns=500_000,
        period_den=3,
        anchored_last=False,
    ),
    # Protocol 6.1, 8 blocks; t0 triggers the last round, block start = t0 + 5.632 us
    # - 50 us per later round.
    "PandarXT16": _general(
        "PandarXT16",
        (6, 1),
        8,
        16,
        _TAIL_XT,
        anchor_ns=5_632,
        period_num_ns=50_000,
        header_max_returns=2,
    ),
    "PandarXT32": _general(
        "PandarXT32",
        (6, 1),
        8,
        32,
        _TAIL_XT,
        anchor_ns=5_632,
        period_num_ns=50_000,
        header_max_returns=2,
    ),
    # XT32M2X: 6 blocks; single (6 rounds), dual (3 x 2) or triple 0x3D (2 x 3) per packet.
    "PandarXT32M": _general(
        "PandarXT32M",
        (6, 1),
        6,
        32,
        _TAIL_XT,
        anchor_ns=5_632,
        period_num_ns=50_000,
        header_max_returns=3,
    ),
    # Protocol 3.2 (QT128C2X): body CRC, optional functional safety (17 B), tail with mode
    # flag; block start = t0 + 9 us - 111.11 us per later round (see decode_hesai notes).
    "PandarQT128": _general(
        "PandarQT128",
        (3, 2),
        2,
        128,
        {
            "len": 26,
            "mode_flag": 5,
            "return_mode": 12,
            "motor": 13,
            "date": 15,
            "us": 21,
            "factory": 25,
        },
        body_trailer_bytes=4,
        fs_bytes_if_flagged=17,
        trailer_bytes=8,
        header_flags=0x05,
        anchor_ns=9_000,
        period_num_ns=111_110,
    ),
    # OT128 (Pandar128E4X), protocol 1.4 (OT128 user manual, section 3.1.2; tier4/nebula
    # Packet128E3X/Pandar128E4X): 2 blocks of azimuth + 128 x (distance, reflectivity)
    # [+ confidence when flag bit 4], body CRC, functional safety (17 B, flag bit 2), tail
    # (reserved 9, azimuth state 2, operational state, return mode, motor speed, date,
    # timestamp, factory), then UDP sequence (bit 0), IMU (22 B, bit 1), tail CRC, digital
    # signature (32 B, bit 3): 861 bytes with flags 0x07. Block start = t0 + 45.724 us
    # (nebula: 43.346 us + the earliest channel's 2.378 us) - 55.556 us per later round.
    "Pandar128E4X": _general(
        "Pandar128E4X",
        (1, 4),
        2,
        128,
        {
            "len": 26,
            "mode_flag": 11,
            "return_mode": 12,
            "motor": 13,
            "date": 15,
            "us": 21,
            "factory": 25,
        },
        unit_bytes=3,
        unit_bytes_if_confidence=4,
        body_trailer_bytes=4,
        fs_bytes_if_flagged=17,
        trailer_bytes=30,
        header_flags=0x07,
        anchor_ns=45_724,
        period_num_ns=55_556,
    ),
    # Protocol 4.1/4.3: uint16 azimuth + uint8 fine azimuth (1/25600 deg), body CRC,
    # Unix-seconds date; block start = t0 - 9.249 us - 41.666 us per round from the last.
    "AT128": _general(
        "AT128",
        (4, 1),
        2,
        128,
        {"len": 32, "motor": 18, "us": 20, "return_mode": 24, "factory": 25, "date": 26},
        block_prefix_bytes=3,
        fine_azimuth=True,
        body_trailer_bytes=4,
        trailer_bytes=8,
        year_base=0,
        azimuth_units_per_deg=25_600,
        anchor_ns=-(9_249 + 41_666),
        period_num_ns=41_666,
    ),
}

_MODELS: Final = tuple(HESAI_LAYOUTS)

_RETURNS_OF_MODE: Final = {
    0x33: 1,  # first
    0x34: 1,  # second
    0x37: 1,  # strongest
    0x38: 1,  # last
    0x39: 2,  # last + strongest
    0x3A: 2,  # first + second
    0x3B: 2,  # first + last
    0x3C: 2,  # first + strongest
    0x3E: 2,  # strongest + second strongest
    0x3D: 3,  # first + last + strongest (XT32M)
}


def returns_per_firing(return_mode: int) -> int:
    """Returns per firing of a Hesai tail Return Mode code (0 for a code the manuals lack)."""
    return _RETURNS_OF_MODE.get(return_mode, 0)


_RETURNS_TABLE: Final = np.zeros(256, dtype=np.int64)
for _code, _r in _RETURNS_OF_MODE.items():
    _RETURNS_TABLE[_code] = _r


def _check_packets(
    data: NDArray[np.uint8], size: NDArray[np.integer]
) -> tuple[NDArray[np.uint8], NDArray[np.int64]]:
    arr = np.asarray(data)
    if arr.dtype != np.uint8 or arr.ndim != 2:
        raise DecodeError(f"packet data must be a 2-D uint8 array, got {arr.dtype} {arr.shape}")
    sz = np.asarray(size).astype(np.int64)
    if sz.shape != (arr.shape[0],):
        raise DecodeError(f"size has shape {sz.shape}, expected ({arr.shape[0]},)")
    if arr.shape[0] == 0:
        raise DecodeError("no packets to decode")
    if int(sz.max()) > arr.shape[1] or int(sz.min()) < 4:
        raise DecodeError(
            f"packet sizes {int(sz.min())}..{int(sz.max())} do not fit rows of {arr.shape[1]} bytes"
        )
    return arr, sz


def _model_codes(data: NDArray[np.uint8], size: NDArray[np.int64]) -> NDArray[np.int64]:
    """Per packet, the index of its model in `_MODELS`, or -1."""
    b0, b1, b2, b3 = (data[:, i].astype(np.int64) for i in range(4))
    width = data.shape[1]
    lasers = data[:, 6].astype(np.int64) if width > 7 else np.zeros_like(b0)
    blocks = data[:, 7].astype(np.int64) if width > 7 else np.zeros_like(b0)
    general = (b0 == 0xEE) & (b1 == 0xFF)
    rules = {
        "Pandar40P": (b0 == 0xFF) & (b1 == 0xEE) & np.isin(size, (1262, 1266)),
        "Pandar64": general & (b2 == 64) & (b3 == 6) & np.isin(size, (1194, 1198)),
        "PandarQT64": general & (b2 == 3) & (b3 == 1),
        "PandarQT128": general & (b2 == 3) & (b3 == 2),
        "AT128": general & (b2 == 4) & ((b3 == 1) | (b3 == 3)),
        "Pandar128E4X": general & (b2 == 1) & (b3 == 4) & (lasers == 128) & (blocks == 2),
        "PandarXT16": general & (b2 == 6) & (b3 == 1) & (blocks == 8) & (lasers == 16),
        "PandarXT32": general & (b2 == 6) & (b3 == 1) & (blocks == 8) & (lasers == 32),
        "PandarXT32M": general & (b2 == 6) & (b3 == 1) & (blocks == 6) & (lasers == 32),
    }
    code = np.full(data.shape[0], -1, dtype=np.int64)
    for i, name in enumerate(_MODELS):
        code[rules[name] & (code < 0)] = i
    return code


def detect_hesai_model(data: NDArray[np.uint8], size: NDArray[np.integer]) -> str:
    """The one Hesai model all packets belong to; DecodeError if unknown or mixed.

    Pandar40P: no pre-header, starts with block flag 0xFFEE, 1262/1266 bytes.
    Pandar64: 0xEEFF, 64 lasers, 6 blocks, 1194/1198 bytes (8-byte header, no version).
    Others: 0xEEFF + protocol major.minor: 1.4 Pandar128E4X (OT128; 128 lasers, 2 blocks),
    3.1 PandarQT64, 3.2 PandarQT128, 4.1/4.3 AT128,
    6.1 PandarXT (8 blocks: 16 or 32 lasers -> XT16/XT32; 6 blocks -> XT32M).
    """
    arr, sz = _check_packets(data, size)
    code = _model_codes(arr, sz)
    bad = np.flatnonzero(code < 0)
    if bad.size:
        i = int(bad[0])
        head = bytes(arr[i, :8]).hex(" ")
        raise DecodeError(
            f"{bad.size} packet(s) are no known Hesai model, first #{i}: "
            f"bytes {head}, size {int(sz[i])}"
        )
    found = distinct(code)
    if found.size > 1:
        names = ", ".join(_MODELS[int(c)] for c in found)
        raise DecodeError(f"packets of more than one Hesai model: {names}")
    return _MODELS[int(found[0])]


def _gather(data: NDArray[np.uint8], start: NDArray[np.int64], count: int) -> NDArray[np.int64]:
    """(n, count) bytes starting at a per-packet column, as int64."""
    first = int(start[0])
    if (start == first).all():  # one tail position (every model but QT128/OT128 mixes)
        return data[:, first : first + count].astype(np.int64)
    cols = start[:, None] + np.arange(count, dtype=np.int64)[None, :]
    return np.take_along_axis(data, cols, axis=1).astype(np.int64)


def _le(b: NDArray[np.int64]) -> NDArray[np.int64]:
    """Little-endian unsigned integer from the bytes along the last axis."""
    weights = np.left_shift(np.int64(1), 8 * np.arange(b.shape[-1], dtype=np.int64))
    out: NDArray[np.int64] = (b * weights).sum(axis=-1, dtype=np.int64)
    return out


def _days_from_civil(
    year: NDArray[np.int64], month: NDArray[np.int64], day: NDArray[np.int64]
) -> NDArray[np.int64]:
    """Days since 1970-01-01 of a proleptic Gregorian date (vectorised)."""
    y: NDArray[np.int64] = year - (month <= 2).astype(np.int64)
    era = y // 400
    yoe = y - era * 400
    doy = (153 * ((month + 9) % 12) + 2) // 5 + day - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    days: NDArray[np.int64] = era * 146_097 + doe - 719_468
    return days


def _epoch_seconds(date: NDArray[np.int64]) -> NDArray[np.int64]:
    """Seconds since the epoch of the 6 date bytes; -1 where unset.

    A first byte of 0 means the bytes 1..5 hold big-endian Unix seconds (AT128). Otherwise
    it is year, month, day, hour, minute, second with the year as year-2000 (values < 100,
    Pandar40P/64) or year-1900 (the rest), as HesaiLidar_SDK_2.0 reads it.
    """
    unix = date[:, 0] == 0
    weights = np.left_shift(np.int64(1), 8 * np.arange(4, -1, -1, dtype=np.int64))
    unix_s = (date[:, 1:] * weights).sum(axis=1)
    year = np.where(date[:, 0] >= 100, 1900, 2000) + date[:, 0]
    month, day, hour, minute, second = (date[:, i] for i in range(1, 6))
    ok = (
        (month >= 1)
        & (month <= 12)
        & (day >= 1)
        & (day <= 31)
        & (hour < 24)
        & (minute < 60)
        & (second <= 60)
    )
    bad = np.flatnonzero(~unix & ~ok)
    if bad.size:
        i = int(bad[0])
        raise DecodeError(f"packet #{i} has an invalid date-time {date[i].tolist()}")
    cal = _days_from_civil(year, month, day) * 86_400 + hour * 3600 + minute * 60 + second
    return np.where(unix, np.where(unix_s == 0, -1, unix_s), cal)


def _packet_layout(data: NDArray[np.uint8], size: NDArray[np.int64]) -> HesaiLayout:
    """The layout of the packets' model, with 4-byte units where the confidence flag is set."""
    layout = HESAI_LAYOUTS[detect_hesai_model(data, size)]
    if not layout.unit_bytes_if_confidence:
        return layout
    confidence = (data[:, 11] & 0x10) != 0
    if not confidence.any():
        return layout
    if not confidence.all():
        i = int(np.argmin(confidence))
        raise DecodeError(
            f"{layout.model} packet #{i} lacks the confidence flag the others carry "
            "(channel units of 3 and 4 bytes mixed)"
        )
    return replace(layout, unit_bytes=layout.unit_bytes_if_confidence)


def _tail_start(layout: HesaiLayout, data: NDArray[np.uint8]) -> NDArray[np.int64]:
    """Per packet, offset of the tail (QT128: depends on the functional-safety flag)."""
    start = np.full(data.shape[0], layout.body_end + layout.body_trailer_bytes, dtype=np.int64)
    if layout.fs_bytes_if_flagged:
        has_fs = (data[:, 11] & 0x04) != 0
        start += np.where(has_fs, layout.fs_bytes_if_flagged, 0)
    return start


def _n_returns(
    layout: HesaiLayout, mode: NDArray[np.int64], azimuth: NDArray[np.int64]
) -> NDArray[np.int64]:
    """Returns per firing, from the tail's return mode, checked against the block azimuths.

    The manuals define the firing grouping by the tail's Return Mode field: in an r-return
    mode one firing fills r adjacent blocks that share its azimuth. The 12-byte header's
    "Return Number"/"Echo Num" byte is not the current mode: the PandarXT manual defines it
    as the most returns a channel can produce (0x02 on XT16/32 in every mode) and an
    XT32M2X writes 3 while in a dual mode (0x3c), so it is not used; tier4/nebula
    (`get_n_returns(tail.return_mode)`) and HesaiLidar_SDK_2.0 (tail `IsDualReturn`) read
    the tail too. An unknown mode code falls back to the azimuth pattern: the largest r
    whose block groups all share one azimuth in every packet.
    """
    first = int(mode[0])
    if (mode == first).all() and _RETURNS_TABLE[first]:  # one known mode: the usual case
        returns = int(_RETURNS_TABLE[first])
        r = np.full(mode.shape, returns, dtype=np.int64)
    else:
        r = _RETURNS_TABLE[mode]
        unknown = r == 0
        if unknown.any():
            r = np.where(unknown, _returns_from_azimuth(layout, azimuth), r)
    bad = np.flatnonzero(layout.n_blocks % np.maximum(r, 1) != 0)
    if bad.size:
        i = int(bad[0])
        raise DecodeError(
            f"{layout.model} packet #{i}: return mode {int(mode[i]):#04x} "
            f"({int(r[i])} returns) cannot group {layout.n_blocks} blocks"
        )
    multi = np.flatnonzero(r > 1)
    if multi.size:
        _check_shared_azimuth(layout, mode, azimuth, r, multi)
    return r


def _returns_from_azimuth(layout: HesaiLayout, azimuth: NDArray[np.int64]) -> NDArray[np.int64]:
    """(n,) the largest returns-per-firing whose block groups share one azimuth (at least 1)."""
    n, b = azimuth.shape
    best = np.ones(n, dtype=np.int64)
    for r in range(2, b + 1):
        if b % r:
            continue
        groups = azimuth.reshape(n, b // r, r)
        shared = (groups == groups[:, :, :1]).all(axis=(1, 2))
        best = np.where(shared, r, best)
    return best


def _check_shared_azimuth(
    layout: HesaiLayout,
    mode: NDArray[np.int64],
    azimuth: NDArray[np.int64],
    r: NDArray[np.int64],
    rows: NDArray[np.intp],
) -> None:
    """DecodeError where a multi-return firing's blocks do not share one azimuth."""
    n = azimuth.shape[0]
    uniform = rows.size == n and (r == r[0]).all()
    for returns in [int(r[0])] if uniform else distinct(r[rows]).tolist():
        sel = rows if uniform else rows[r[rows] == returns]
        picked = azimuth if uniform else azimuth[sel]
        groups = picked.reshape(sel.size, layout.n_blocks // returns, returns)
        split = np.flatnonzero(~(groups == groups[:, :, :1]).all(axis=(1, 2)))
        if split.size:
            i = int(sel[split[0]])
            raise DecodeError(
                f"{layout.model} packet #{i}: return mode {int(mode[i]):#04x} says "
                f"{returns} returns per firing, but its blocks' azimuths "
                f"{azimuth[i].tolist()} are not grouped by {returns}"
            )


def decode_hesai(
    data: NDArray[np.uint8], size: NDArray[np.integer], host_stamp_ns: NDArray[np.int64]
) -> PacketTiming:
    """Timing of Hesai point-cloud packets (one model), vectorised over packets.

    `data` (n, L) uint8 rows hold the packets (e.g. the (n, 1500) view of a PandarScan),
    `size` (n,) their lengths, `host_stamp_ns` (n,) the driver stamps. The host stamp is used
    only where a packet's date field is unset (all zero): the whole second is then taken
    from it, the microseconds from the packet.

    `sensor_time_ns` is the packet time t0 = date-time + microsecond timestamp (tail).
    `block_time_ns` is each block's first firing: Pandar40P/64 from the manual's block end
    times minus the earliest channel offset; the others from the manuals' block start times
    (QT64 t0 + 25.71 us + 166.67 us * k; XT t0 + 5.632 us - 50 us * later rounds; QT128
    t0 + 9 us - 111.11 us * later rounds, the ordering monotone in azimuth, whereas nebula
    adds 111.11 us to block 1 - unverified without a QT128 recording; AT128 t0 - 50.915 us
    - 41.666 us * later rounds; OT128 t0 + 45.724 us - 55.556 us * later rounds, nebula's
    numbers). In an r-return mode (r from the tail's return mode, see `_n_returns`) r
    adjacent blocks hold one firing and share its time: XT32M's 6 blocks are 6 rounds
    (single), 3 x 2 (dual) or 2 x 3 (triple 0x3D). For the XT32M in a dual mode nebula
    computes the rounds as if the packet had 8 blocks (last round t0 - 44.4 us); the PandarXT
    manual's rule (t0 triggers the round in the last blocks) is followed here.
    `block_azimuth_deg` is the packet's azimuth field: 0.01 deg; AT128 adds a fine byte
    (1/25600 deg) and reports the raw mirror-encoder angle, not the corrected field angle.
    """
    arr, sz = _check_packets(data, size)
    host = np.asarray(host_stamp_ns, dtype=np.int64)
    if host.shape != sz.shape:
        raise DecodeError(f"host_stamp_ns has shape {host.shape}, expected {sz.shape}")
    layout = _packet_layout(arr, sz)
    n = arr.shape[0]
    if layout.header_bytes == 12:
        lasers, blocks = arr[:, 6], arr[:, 7]
        if (lasers != layout.n_channels).any() or (blocks != layout.n_blocks).any():
            raise DecodeError(
                f"{layout.model} header declares {int(lasers[0])} lasers x {int(blocks[0])} "
                f"blocks, layout has {layout.n_channels} x {layout.n_blocks}"
            )
    tail = _tail_start(layout, arr)
    need = tail + layout.tail_bytes
    short = np.flatnonzero(sz < need)
    if short.size:
        i = int(short[0])
        raise DecodeError(
            f"{layout.model} packet #{i} has {int(sz[i])} bytes, needs {int(need[i])}"
        )
    if layout.valid_sizes and not np.isin(sz, layout.valid_sizes).all():
        raise DecodeError(f"{layout.model} packets must be {layout.valid_sizes} bytes long")

    # Blocks: a zero-copy (n, B, block) view, then the azimuth columns.
    body = arr[:, layout.header_bytes : layout.body_end].reshape(
        n, layout.n_blocks, layout.block_bytes
    )
    if (
        layout.model == "Pandar40P"
        and not ((body[:, :, 0] == 0xFF) & (body[:, :, 1] == 0xEE)).all()
    ):
        raise DecodeError("Pandar40P block without its 0xFFEE start flag")
    a = layout.azimuth_offset
    azimuth = body[:, :, a].astype(np.int64) | (body[:, :, a + 1].astype(np.int64) << 8)
    if layout.fine_azimuth:
        azimuth = (azimuth << 8) | body[:, :, a + 2]
    full_turn = 360 * layout.azimuth_units_per_deg
    if int(azimuth.max()) >= full_turn:
        i = int(np.argmax(azimuth.max(axis=1)))
        raise DecodeError(
            f"{layout.model} packet #{i}: azimuth {int(azimuth[i].max())} is past 360 deg"
        )

    mode = _gather(arr, tail + layout.tail_return_mode, 1)[:, 0]
    n_ret = _n_returns(layout, mode, azimuth)
    motor_rpm = _le(_gather(arr, tail + layout.tail_motor_rpm, 2))
    us = _le(_gather(arr, tail + layout.tail_timestamp_us, 4))
    if int(us.max()) > 1_000_000:
        i = int(np.argmax(us))
        raise DecodeError(
            f"{layout.model} packet #{i}: microsecond timestamp {int(us[i])} is past 1 s"
        )
    seconds = _epoch_seconds(_gather(arr, tail + layout.tail_date_time, 6))
    unset = seconds < 0
    if unset.any():
        host_s = (host - us * 1000 + _NS_PER_S // 2) // _NS_PER_S  # nearest whole second
        seconds = np.where(unset, host_s, seconds)
    t0_ns = seconds * _NS_PER_S + us * 1000
    return PacketTiming(
        vendor="hesai",
        model=layout.model,
        sensor_time_ns=t0_ns,
        block_azimuth_deg=azimuth / layout.azimuth_units_per_deg,
        block_time_ns=t0_ns[:, None] + layout.block_offset_ns(n_ret),
        return_mode=mode.astype(np.uint8),
        dual_return=n_ret >= 2,
        motor_rpm=motor_rpm.astype(np.float64),
    )


def hesai_returns(
    data: NDArray[np.uint8], size: NDArray[np.integer]
) -> tuple[NDArray[np.float64], NDArray[np.uint8]]:
    """Per block and channel: distance in metres (0 = no return) and reflectivity.

    Shapes (n, B, C); the distance unit is the header's (4 mm; Pandar40P: fixed 4 mm).
    """
    arr, sz = _check_packets(data, size)
    layout = _packet_layout(arr, sz)
    n = arr.shape[0]
    body = arr[:, layout.header_bytes : layout.body_end].reshape(
        n, layout.n_blocks, layout.block_bytes
    )
    units = body[:, :, layout.block_prefix_bytes :].reshape(
        n, layout.n_blocks, layout.n_channels, layout.unit_bytes
    )
    raw = units[..., 0].astype(np.uint16) | (units[..., 1].astype(np.uint16) << 8)
    if layout.model == "Pandar40P":
        unit_m = np.full(n, 0.004)
    else:
        unit_m = arr[:, 5 if layout.header_bytes == 8 else 9] / 1000.0
    return raw * unit_m[:, None, None], units[..., 2].copy()
