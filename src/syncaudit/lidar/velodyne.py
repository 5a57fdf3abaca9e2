"""Velodyne: views over velodyne_msgs/VelodyneScan bytes and packet timing decode.

A Velodyne data packet is 1206 bytes: 12 data blocks of 100 bytes (2-byte flag, 2-byte
azimuth in hundredths of a degree, 32 records of distance uint16 + intensity uint8), a
4-byte time stamp (microseconds past the top of the hour, sensor clock), the return-mode
byte (0x37 strongest, 0x38 last, 0x39 dual) and the product-id byte. All multi-byte fields
are little endian.

Timing follows the vendor manuals (all constants are whole nanoseconds, so times are exact
int64 arithmetic):

- VLP-16 / Puck Hi-Res: 16 lasers fired 2.304 us apart, a firing sequence every 55.296 us,
  two sequences per block; the stamp is the first firing of the packet.
- VLP-32C: 32 lasers fired in 16 pairs 2.304 us apart, one 55.296 us sequence per block;
  the stamp is the first firing of the packet.
- HDL-32E: 32 lasers fired 1.152 us apart, one 46.08 us sequence per block; its manual's
  Ethernet transit timing table puts the stamp at the *last* firing of the packet
  (first firing = stamp - 542.592 us in single-return mode).
- VLS-128: 128 lasers fired in groups of 8 every 2.665 us (a maintenance slot after group
  7), a 53.3 us sequence spans four blocks (banks 0xEEFF, 0xDDFF, 0xCCFF, 0xBBFF); the
  manual's exact point time is stamp + offset - 8.7 us.
- HDL-64E (S2/S2.1 transit timing table): upper (0xEEFF) and lower (0xDDFF) blocks fire
  together, 0.728 us per laser, 23.296 us per block pair, first firing 419.30 us before
  the stamp. No product byte; detected from the alternating flags. Single return only.

In dual-return mode (0x39) blocks come in pairs that share azimuth and firing times.
`PacketTiming.block_time_ns` is the block's first firing (VLS-128: its sequence's first
firing, the instant its azimuth was sampled), `sensor_time_ns` the stamp itself.

Azimuths are the vendor's: degrees clockwise seen from above, as in the packet. The
per-firing azimuth is the manual's "precision azimuth": the block azimuth advanced by the
gap to the next azimuth sample of the same bank, pro rata of the firing's time within that
span; the last block of a packet reuses the previous gap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from typing import Final, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from syncaudit.errors import DecodeError
from syncaudit.lidar.packets import PacketTiming
from syncaudit.logs.wire import WireError, cdr_align, cdr_byte_order, cdr_header, ros1_header

PACKET_BYTES: Final = 1206
BLOCKS: Final = 12
RECORDS: Final = 32
BLOCK_BYTES: Final = 100
TOH_OFFSET: Final = 1200
RETURN_MODE_OFFSET: Final = 1204
PRODUCT_ID_OFFSET: Final = 1205

RETURN_STRONGEST: Final = 0x37
RETURN_LAST: Final = 0x38
RETURN_DUAL: Final = 0x39
RETURN_MODES: Final = (RETURN_STRONGEST, RETURN_LAST, RETURN_DUAL)

HOUR_US: Final = 3_600_000_000
HOUR_NS: Final = 3_600_000_000_000

BANK_FLAGS: Final = (0xEEFF, 0xDDFF, 0xCCFF, 0xBBFF)
"""Block flags as little-endian uint16 (bytes FF EE, FF DD, FF CC, FF BB)."""

PRODUCT_IDS: Final[dict[int, str]] = {
    0x21: "HDL-32E",
    0x22: "VLP-16",
    0x24: "Puck Hi-Res",
    0x28: "VLP-32C",
    0xA1: "VLS-128",
}
"""Factory byte 1205 -> model. The HDL-64E has no product byte."""

MODEL_PRODUCT_ID: Final[dict[str, int]] = {v: k for k, v in PRODUCT_IDS.items()}
ENCODABLE_MODELS: Final = ("VLP-16", "Puck Hi-Res", "VLP-32C", "HDL-32E", "VLS-128")
WRAP_AZIMUTH_RAW: Final = 36000
"""The azimuth field at the wrap: real sensors write it for 0 (hundredths of a degree)."""
SHARED_ID_MODELS: Final = ("HDL-32E", "VLP-16")
"""Models that product id 0x21 may name: early VLP-16 firmware wrote the HDL-32E's id."""
MAX_RPM: Final = 1500.0
"""Gaps between azimuth samples beyond this rotation speed are not rotation (FOV cut)."""

DISTANCE_RESOLUTION_M: Final[dict[str, float]] = {
    "VLP-16": 0.002,
    "Puck Hi-Res": 0.002,
    "HDL-32E": 0.002,
    "HDL-64E": 0.002,
    "VLP-32C": 0.004,
    "VLS-128": 0.004,
}

# Timing constants in nanoseconds, from the user manuals.
VLP16_SEQUENCE_NS: Final = 55_296
VLP16_FIRING_NS: Final = 2_304
VLP32C_SEQUENCE_NS: Final = 55_296
VLP32C_FIRING_NS: Final = 2_304
HDL32E_SEQUENCE_NS: Final = 46_080
HDL32E_FIRING_NS: Final = 1_152
VLS128_SEQUENCE_NS: Final = 53_300
VLS128_GROUP_NS: Final = 2_665
VLS128_STAMP_AFTER_FIRST_NS: Final = 8_700
HDL64E_LASER_NS: Final = 728
HDL64E_PAIR_NS: Final = 23_296
HDL64E_STAMP_AFTER_FIRST_NS: Final = 419_300

_THIRD = 1.0 / 3.0
VLP32C_ELEVATION_DEG: Final = (
    -25.0, -1.0, -1.667, -15.639, -11.31, 0.0, -0.667, -8.843,
    -7.254, 0.333, -0.333, -6.148, -5.333, 1.333, 0.667, -4.0,
    -4.667, 1.667, 1.0, -3.667, -3.333, 3.333, 2.333, -2.667,
    -3.0, 7.0, 4.667, -2.333, -2.0, 15.0, 10.333, -1.333,
)  # fmt: skip
"""VLP-32C nominal vertical angle per laser id (data order), from the manual."""
VLP32C_AZIMUTH_OFFSET_DEG: Final = (
    1.4, -4.2, 1.4, -1.4, 1.4, -1.4, 4.2, -1.4,
    1.4, -4.2, 1.4, -1.4, 4.2, -1.4, 4.2, -1.4,
    1.4, -4.2, 1.4, -4.2, 4.2, -1.4, 1.4, -1.4,
    1.4, -1.4, 1.4, -4.2, 4.2, -1.4, 1.4, -1.4,
)  # fmt: skip
"""VLP-32C nominal horizontal offset per laser id: beam azimuth = rotor azimuth + offset."""


# --------------------------------------------------------------------------------------
# ROS message views
# --------------------------------------------------------------------------------------

Bytes = bytes | bytearray | memoryview
_CDR_PACKET_STRIDE: Final = 1216  # stamp 8 + data 1206 = 1214, next packet 4-aligned
_ROS1_PACKET_STRIDE: Final = 1214
_ENCODINGS: Final = ("cdr", "ros1")


def _u8(raw: Bytes) -> NDArray[np.uint8]:
    """Zero-copy uint8 view of a bytes-like object."""
    return np.frombuffer(raw, dtype=np.uint8)


def _check_encoding(encoding: str) -> None:
    if encoding not in _ENCODINGS:
        raise ValueError(f"encoding must be one of {_ENCODINGS}, not {encoding!r}")


def _align4(offset: int) -> int:
    """`offset` rounded up to a multiple of 4 (the encoder's CDR padding)."""
    return (offset + 3) & ~3


@dataclass(frozen=True, slots=True)
class _ScanLayout:
    """Where the parts of one serialized VelodyneScan sit in its bytes."""

    endian: str
    stamp_ns: int
    frame_id: str
    count: int
    first_packet: int
    stride: int


def _scan_layout(buf: NDArray[np.uint8], encoding: str) -> _ScanLayout:
    """Parse the fixed head of a VelodyneScan message and validate the total length."""
    _check_encoding(encoding)
    size = int(buf.size)
    mem = buf.data
    try:
        if encoding == "cdr":
            endian = cdr_byte_order(mem)
            sec, nsec, frame_id, pos = cdr_header(mem, 4, endian)
            pos = cdr_align(pos, 4)
        else:
            endian = "<"
            _seq, sec, nsec, frame_id, pos = ros1_header(mem, 0)
    except WireError as exc:
        raise DecodeError(f"VelodyneScan: {exc}") from None
    if pos + 4 > size:
        raise DecodeError(f"VelodyneScan: packet count runs past {size} bytes")
    count = int.from_bytes(bytes(buf[pos : pos + 4]), "little" if endian == "<" else "big")
    first = pos + 4
    if encoding == "cdr":
        stride = _CDR_PACKET_STRIDE
        end = first + (count - 1) * stride + 1214 if count else first
        allowed = (end, cdr_align(end, 4))
    else:
        stride = _ROS1_PACKET_STRIDE
        end = first + count * stride
        allowed = (end, end)
    if size not in allowed:
        raise DecodeError(
            f"VelodyneScan: {count} packets need {end} bytes ({encoding}), message has {size}"
        )
    if nsec >= 1_000_000_000:
        raise DecodeError(f"VelodyneScan: header nanoseconds {nsec} out of range")
    return _ScanLayout(endian, sec * 1_000_000_000 + nsec, frame_id, count, first, stride)


def velodyne_scan_header(raw: Bytes, encoding: str = "cdr") -> tuple[int, str]:
    """(header stamp in ns, frame_id) of one serialized velodyne_msgs/VelodyneScan."""
    layout = _scan_layout(_u8(raw), encoding)
    return layout.stamp_ns, layout.frame_id


def velodyne_scan_packets(
    raw: Bytes, encoding: str = "cdr"
) -> tuple[NDArray[np.int64], NDArray[np.uint8]]:
    """Per-packet driver stamps (n,) in ns and a zero-copy (n, 1206) view of the packet bytes.

    `encoding` is "cdr" (ROS 2, XCDR1 with the 4-byte encapsulation header, either endian;
    packets 4-aligned, stride 1216) or "ros1" (stride 1214). No per-packet Python loop: the
    stamps and data are strided numpy views over `raw`, so they live as long as `raw` does.
    """
    buf = _u8(raw)
    layout = _scan_layout(buf, encoding)
    n, first, stride, e = layout.count, layout.first_packet, layout.stride, layout.endian
    if n == 0:
        return np.zeros(0, dtype=np.int64), np.zeros((0, PACKET_BYTES), dtype=np.uint8)
    sec_type = e + ("i4" if encoding == "cdr" else "u4")
    sec = np.ndarray((n,), dtype=sec_type, buffer=buf, offset=first, strides=(stride,))
    nsec = np.ndarray((n,), dtype=e + "u4", buffer=buf, offset=first + 4, strides=(stride,))
    data = np.ndarray(
        (n, PACKET_BYTES), dtype=np.uint8, buffer=buf, offset=first + 8, strides=(stride, 1)
    )
    if int(nsec.max()) >= 1_000_000_000:
        raise DecodeError("VelodyneScan: a packet stamp has nanoseconds >= 1e9")
    stamps = sec.astype(np.int64) * 1_000_000_000 + nsec
    return stamps, data


# --------------------------------------------------------------------------------------
# Per-model layout tables
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class _Layout:
    """Where and when each of the 12 x 32 records of a packet was fired, for one mode."""

    laser_id: NDArray[np.int16]
    """(12, 32) laser id of each record; -1 in padding blocks."""
    firing_ns: NDArray[np.int64]
    """(12, 32) firing time minus the packet stamp."""
    since_azimuth_ns: NDArray[np.int64]
    """(12, 32) firing time minus the time the block's azimuth was sampled."""
    sequence: NDArray[np.int16]
    """(12, 32) firing sequence index within the packet."""
    next_block: NDArray[np.intp]
    """(12,) next block carrying a later azimuth sample of the same bank, -1 if none."""
    prev_block: NDArray[np.intp]
    """(12,) previous such block, -1 if none."""
    flags: NDArray[np.uint16]
    """(12,) expected block flags; 0 where any flag is accepted (padding)."""
    span_ns: int
    """Time between two successive azimuth samples of one bank."""
    packet_ns: int
    """Time from one packet's first firing to the next one's at a steady rate."""


def _layout_arrays(
    laser: NDArray[np.int64],
    since: NDArray[np.int64],
    sample_seq: NDArray[np.int64],
    seq: NDArray[np.int64],
    seq_ns: int,
    first_from_stamp_ns: int,
    step: int,
    flags: NDArray[np.int64],
    span_ns: int,
    packet_ns: int,
    real_blocks: int = BLOCKS,
) -> _Layout:
    """Assemble a _Layout from per-record laser ids, offsets and sequence indices.

    `since` is each firing's time after the block's azimuth sample, taken at the start of
    sequence `sample_seq`; `seq` is the sequence the firing belongs to.
    """
    b = np.arange(BLOCKS)
    nxt = np.where(b + step < real_blocks, b + step, -1)
    prv = np.where(b - step >= 0, b - step, -1)
    nxt[real_blocks:] = -1
    prv[real_blocks:] = -1
    firing = first_from_stamp_ns + sample_seq * seq_ns + since
    return _Layout(
        laser_id=laser.astype(np.int16),
        firing_ns=firing.astype(np.int64),
        since_azimuth_ns=since.astype(np.int64),
        sequence=seq.astype(np.int16),
        next_block=nxt.astype(np.intp),
        prev_block=prv.astype(np.intp),
        flags=flags.astype(np.uint16),
        span_ns=span_ns,
        packet_ns=packet_ns,
    )


@cache
def _layout(model: str, dual: bool) -> _Layout:
    """Firing layout of one model in single (dual=False) or dual-return mode."""
    b = np.arange(BLOCKS)[:, None]
    j = np.arange(RECORDS)[None, :]
    ones = np.ones((BLOCKS, RECORDS), dtype=np.int64)
    ee = np.full(BLOCKS, BANK_FLAGS[0], dtype=np.int64)
    if model in ("VLP-16", "Puck Hi-Res"):
        pair = b // 2 if dual else b
        seq = 2 * pair + j // 16
        since = (j // 16) * VLP16_SEQUENCE_NS + (j % 16) * VLP16_FIRING_NS
        n_seq = 12 if dual else 24
        return _layout_arrays(
            (j % 16) * ones, since * ones, 2 * pair * ones, seq * ones, VLP16_SEQUENCE_NS, 0,
            2 if dual else 1, ee, 2 * VLP16_SEQUENCE_NS, n_seq * VLP16_SEQUENCE_NS,
        )  # fmt: skip
    if model == "VLP-32C":
        seq = b // 2 if dual else b
        since = (j // 2) * VLP32C_FIRING_NS
        n_seq = 6 if dual else 12
        return _layout_arrays(
            j * ones, since * ones, seq * ones, seq * ones, VLP32C_SEQUENCE_NS, 0,
            2 if dual else 1, ee, VLP32C_SEQUENCE_NS, n_seq * VLP32C_SEQUENCE_NS,
        )  # fmt: skip
    if model == "HDL-32E":
        seq = b // 2 if dual else b
        since = j * HDL32E_FIRING_NS
        n_seq = 6 if dual else 12
        # The stamp is the last firing of the packet (manual's transit timing table).
        first = -((n_seq - 1) * HDL32E_SEQUENCE_NS + (RECORDS - 1) * HDL32E_FIRING_NS)
        return _layout_arrays(
            j * ones, since * ones, seq * ones, seq * ones, HDL32E_SEQUENCE_NS, first,
            2 if dual else 1, ee, HDL32E_SEQUENCE_NS, n_seq * HDL32E_SEQUENCE_NS,
        )  # fmt: skip
    if model == "VLS-128":
        if dual:
            bank = np.where(b < 8, (b // 2) % 4, 3)
            seq = 0 * b
            flags = np.array([BANK_FLAGS[k // 2] for k in range(8)] + [0] * 4, dtype=np.int64)
            step, real, n_seq = 8, 8, 1
        else:
            bank = b % 4
            seq = b // 4
            flags = np.array([BANK_FLAGS[k % 4] for k in range(BLOCKS)], dtype=np.int64)
            step, real, n_seq = 4, BLOCKS, 3
        laser = 32 * bank + j
        group = laser // 8 + laser // 64  # a maintenance slot after the 8th firing group
        since = group * VLS128_GROUP_NS
        laser = np.where(b < real, laser, -1)
        return _layout_arrays(
            laser * ones, since * ones, seq * ones, seq * ones, VLS128_SEQUENCE_NS,
            -VLS128_STAMP_AFTER_FIRST_NS, step, flags, VLS128_SEQUENCE_NS,
            n_seq * VLS128_SEQUENCE_NS, real,
        )  # fmt: skip
    if model == "HDL-64E":
        flags = np.array([BANK_FLAGS[k % 2] for k in range(BLOCKS)], dtype=np.int64)
        return _layout_arrays(
            (32 * (b % 2) + j) * ones, j * HDL64E_LASER_NS * ones, (b // 2) * ones,
            (b // 2) * ones, HDL64E_PAIR_NS, -HDL64E_STAMP_AFTER_FIRST_NS, 2, flags, HDL64E_PAIR_NS,
            6 * HDL64E_PAIR_NS,
        )  # fmt: skip
    raise ValueError(f"unknown Velodyne model {model!r}")


def velodyne_firing_offsets_ns(model: str, dual: bool) -> NDArray[np.int64]:
    """(12, 32) firing time of each record minus the packet stamp, per the model's manual."""
    if model == "HDL-64E" and dual:
        raise ValueError("HDL-64E dual-return timing is not modelled")
    return _layout(model, dual).firing_ns.copy()


def velodyne_laser_angles(model: str) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Nominal (elevation_deg, azimuth_offset_deg) per laser id, in packet data order.

    Factory nominal values (per-unit calibration files refine them). Beam azimuth =
    rotor azimuth + offset. Known for VLP-16, Puck Hi-Res, HDL-32E and VLP-32C.
    """
    i = np.arange(32)
    if model == "VLP-16":
        elev = np.where(i[:16] % 2 == 0, -15.0 + i[:16], i[:16].astype(np.float64))
        return elev.astype(np.float64), np.zeros(16)
    if model == "Puck Hi-Res":
        k = (i[:16] // 2) * 4.0 * _THIRD
        elev = np.where(i[:16] % 2 == 0, -10.0 + k, 2.0 * _THIRD + k)
        return elev.astype(np.float64), np.zeros(16)
    if model == "HDL-32E":
        k = (i // 2) * 4.0 * _THIRD
        elev = np.where(i % 2 == 0, -92.0 * _THIRD + k, -28.0 * _THIRD + k)
        return elev.astype(np.float64), np.zeros(32)
    if model == "VLP-32C":
        return np.array(VLP32C_ELEVATION_DEG), np.array(VLP32C_AZIMUTH_OFFSET_DEG)
    raise ValueError(f"no nominal laser angles for {model!r}")


# --------------------------------------------------------------------------------------
# Decode
# --------------------------------------------------------------------------------------

_BLOCK_HEAD: Final = np.dtype(
    {
        "names": ["flag", "azimuth"],
        "formats": ["<u2", "<u2"],
        "offsets": [0, 2],
        "itemsize": BLOCK_BYTES,
    }
)
"""The head of a data block: flag and azimuth (the records after them are not read)."""
_PACKET_HEAD: Final = np.dtype(
    {
        "names": ["block", "toh_us", "return_mode", "product_id"],
        "formats": [(_BLOCK_HEAD, (BLOCKS,)), "<u4", "u1", "u1"],
        "offsets": [0, TOH_OFFSET, RETURN_MODE_OFFSET, PRODUCT_ID_OFFSET],
        "itemsize": PACKET_BYTES,
    }
)
"""The fields of a packet that timing reads, laid over its 1206 bytes."""

_Scalar = TypeVar("_Scalar", bound=np.generic)
_HDL64E_FLAGS: Final = [BANK_FLAGS[k % 2] for k in range(BLOCKS)]
_KNOWN_RETURN_MODE: Final = np.isin(np.arange(256), RETURN_MODES)
"""Lookup table: True at the return-mode bytes a packet may carry."""


def _fields(data: NDArray[np.uint8]) -> NDArray[np.void]:
    """(n,) structured view of the packet fields (copied first if a packet is not contiguous).

    Each field then costs one numpy call instead of an astype and shift per byte.
    """
    if data.strides[1] != 1:
        data = np.ascontiguousarray(data)
    fields: NDArray[np.void] = data.view(_PACKET_HEAD)[:, 0]
    return fields


def _flags(fields: NDArray[np.void]) -> NDArray[np.uint16]:
    """(n, 12) block flags as little-endian uint16 (a view)."""
    flags: NDArray[np.uint16] = fields["block"]["flag"]
    return flags


def _toh_us(fields: NDArray[np.void]) -> NDArray[np.int64]:
    """(n,) the 4-byte time stamp, microseconds past the hour."""
    return fields["toh_us"].astype(np.int64)


def detect_velodyne_model(data: NDArray[np.uint8]) -> str:
    """Model of a packet array from its first packet: product byte, or HDL-64E flag pattern."""
    arr = _check_packets(data)
    if arr.shape[0] == 0:
        raise DecodeError("no Velodyne packets to detect a model from")
    return _first_packet_model(_fields(arr[:1]))


def _first_packet_model(fields: NDArray[np.void]) -> str:
    """detect_velodyne_model on the fields of a non-empty packet array."""
    if _flags(fields)[0].tolist() == _HDL64E_FLAGS:
        return "HDL-64E"
    pid = int(fields["product_id"][0])
    model = PRODUCT_IDS.get(pid)
    if model is None:
        raise DecodeError(f"Velodyne product id 0x{pid:02X} is not a supported model")
    return model


def _check_packets(data: NDArray[np.uint8]) -> NDArray[np.uint8]:
    arr = np.asarray(data)
    if arr.dtype != np.uint8 or arr.ndim != 2 or arr.shape[1] != PACKET_BYTES:
        raise DecodeError(
            f"Velodyne packets must be (n, {PACKET_BYTES}) uint8, got {arr.shape} {arr.dtype}"
        )
    return arr


@dataclass(frozen=True, slots=True)
class _Decoded:
    """What decode_velodyne and velodyne_firing_times share."""

    timing: PacketTiming
    azimuth_raw: NDArray[np.int64]
    dual_index: NDArray[np.intp]


@dataclass(frozen=True, slots=True)
class _ModeTables:
    """Per-block constants of one model for decoding; row 0 single return, row 1 dual."""

    flags: NDArray[np.uint16]
    """(2, 12) expected block flags; 0 where any flag is accepted (padding)."""
    real: NDArray[np.bool_]
    """(2, 12) True for blocks that carry data (not padding)."""
    fill: NDArray[np.intp]
    """(2, 12) block whose azimuth each block reports: itself, or for padding the last
    real block of the packet."""
    block_offset_ns: NDArray[np.int64]
    """(2, 12) block_time_ns minus the packet stamp (padding as its fill block)."""


@cache
def _mode_tables(model: str) -> _ModeTables:
    """_ModeTables of `model`, built once from its two _Layouts (not on every decode)."""
    b = np.arange(BLOCKS)
    flags, real, fill, offset = [], [], [], []
    for dual in (False, True):
        lay = _layout(model, dual)
        is_real = lay.flags != 0
        block_fill = np.where(is_real, b, b[is_real].max())
        sample = b
        if model == "VLS-128":
            # All four banks of a firing sequence carry the azimuth sampled at the sequence
            # start, so that is the time each block's azimuth belongs to (PacketTiming).
            sample = np.zeros(BLOCKS, dtype=np.int64) if dual else (b // 4) * 4
        flags.append(lay.flags)
        real.append(is_real)
        fill.append(block_fill)
        offset.append(lay.firing_ns[sample[block_fill], 0])
    return _ModeTables(
        flags=np.stack(flags).astype(np.uint16),
        real=np.stack(real),
        fill=np.stack(fill).astype(np.intp),
        block_offset_ns=np.stack(offset).astype(np.int64),
    )


def _per_packet(table: NDArray[_Scalar], dual: NDArray[np.bool_]) -> NDArray[_Scalar]:
    """Each packet's row of a (2, 12) per-mode table: (n, 12), or (12,) to broadcast when
    all packets share one mode (the common case, and cheaper than a gather)."""
    mode: int | NDArray[np.intp]
    if not dual.any():
        mode = 0
    elif dual.all():
        mode = 1
    else:
        mode = dual.astype(np.intp)
    rows: NDArray[_Scalar] = table[mode]
    return rows


def resolve_hour_ns(toh_us: ArrayLike, host_stamp_ns: ArrayLike) -> NDArray[np.int64]:
    """Full-epoch sensor time of microseconds-past-the-hour stamps, hour taken from the host.

    The hour is the one that puts the sensor time closest to the host stamp, so sensor
    clocks more than 30 min off the host are resolved to the wrong hour (an exact hour
    error): the packet stamp alone cannot tell.
    """
    toh_ns: NDArray[np.int64] = np.asarray(toh_us, dtype=np.int64) * 1000
    host: NDArray[np.int64] = np.asarray(host_stamp_ns, dtype=np.int64)
    candidate = (host // HOUR_NS) * HOUR_NS + toh_ns
    k = (host - candidate + HOUR_NS // 2) // HOUR_NS
    sensor: NDArray[np.int64] = candidate + k * HOUR_NS
    return sensor


def _return_modes(fields: NDArray[np.void], model: str) -> NDArray[np.uint8]:
    """(n,) return-mode bytes, checked together with the product byte (HDL-64E: zeros):
    every packet must carry the first packet's product byte."""
    n = fields.shape[0]
    if model == "HDL-64E":
        return np.zeros(n, dtype=np.uint8)
    rmode: NDArray[np.uint8] = fields["return_mode"].copy()
    known = _KNOWN_RETURN_MODE[rmode]
    if not known.all():
        i = int(np.argmin(known))
        raise DecodeError(f"packet {i}: return-mode byte 0x{int(rmode[i]):02X} is unknown")
    pid = fields["product_id"]
    mixed = pid != pid[0]
    if mixed.any():
        i = int(np.argmax(mixed))
        raise DecodeError(f"packet {i}: product id 0x{int(pid[i]):02X} differs from {model}")
    return rmode


def packet_gap_us(toh_us: NDArray[np.int64]) -> float:
    """Median gap between consecutive packet stamps (us, across the hour), NaN below two
    packets or when no gap is positive."""
    if toh_us.size < 2:
        return float("nan")
    gaps = np.diff(toh_us) % HOUR_US
    gaps = gaps[(gaps > 0) & (gaps < HOUR_US // 2)]
    return float(np.median(gaps)) if gaps.size else float("nan")


def model_by_cadence(id_model: str, gap_us: float, dual: bool) -> str:
    """The model of SHARED_ID_MODELS whose packet period (for the return mode) is nearest
    the measured packet gap, in ratio: a VLP-16 sends a packet every 1327 us single-return,
    an HDL-32E every 553 us, whatever the RPM. `id_model` where the gap is unknown."""
    if id_model not in SHARED_ID_MODELS or not gap_us > 0:
        return id_model
    return min(
        SHARED_ID_MODELS, key=lambda m: abs(math.log(gap_us * 1000.0 / _layout(m, dual).packet_ns))
    )


def _resolve_model(
    fields: NDArray[np.void], rmode: NDArray[np.uint8], id_model: str, stated: str | None
) -> str:
    """The model to time the packets as: the rig's where it states one (it must be a model
    the product byte can name), else the product byte's, told apart by cadence where the
    byte is ambiguous (0x21: HDL-32E or early VLP-16)."""
    if stated:
        if stated not in PRODUCT_IDS.values() and stated != "HDL-64E":
            raise DecodeError(f"Velodyne model {stated!r} (from the rig) is not a known model")
        compatible = stated == id_model or {stated, id_model} <= set(SHARED_ID_MODELS)
        if not compatible:
            raise DecodeError(
                f"the rig states {stated} but the packets' product byte says {id_model}"
            )
        return stated
    if id_model not in SHARED_ID_MODELS:  # the byte names one model: no cadence needed
        return id_model
    return model_by_cadence(id_model, packet_gap_us(_toh_us(fields)), bool(rmode[0] == RETURN_DUAL))


def _check_flags(
    fields: NDArray[np.void], model: str, tables: _ModeTables, dual: NDArray[np.bool_]
) -> None:
    """Raise on the first block whose flag is not the one its model and mode expect."""
    flags = _flags(fields)
    bad = flags != _per_packet(tables.flags, dual)
    real = _per_packet(tables.real, dual)
    if not real.all():
        bad &= real
    if bad.any():
        i, blk = (int(v) for v in np.argwhere(bad)[0])
        expected = int(tables.flags[int(dual[i]), blk])
        raise DecodeError(
            f"packet {i} block {blk}: flag 0x{int(flags[i, blk]):04X} is not a {model} "
            f"block flag (expected 0x{expected:04X})"
        )


def _azimuth_raw(
    fields: NDArray[np.void], tables: _ModeTables, dual: NDArray[np.bool_]
) -> tuple[NDArray[np.int64], int]:
    """(n, 12) block azimuths in hundredths of a degree, checked, and the number of real
    blocks that read 36000; padding blocks repeat the last real block of their packet.

    Real sensors write 36000 at the wrap (between 35979 and 18, say): it is 0, as
    ros-drivers/velodyne takes azimuths modulo 36000. Larger values are no azimuth.
    """
    az_raw: NDArray[np.int64] = fields["block"]["azimuth"].astype(np.int64)
    too_big = az_raw > WRAP_AZIMUTH_RAW
    wrap = az_raw == WRAP_AZIMUTH_RAW
    real = _per_packet(tables.real, dual)
    padded = not real.all()
    if padded:
        too_big &= real
        wrap &= real
    if too_big.any():
        i, blk = (int(v) for v in np.argwhere(too_big)[0])
        raise DecodeError(f"packet {i} block {blk}: azimuth {int(az_raw[i, blk])} > 36000")
    wraps = int(np.count_nonzero(wrap))
    if wraps:
        az_raw = az_raw % WRAP_AZIMUTH_RAW
    if padded:
        rows = np.arange(az_raw.shape[0])[:, None]
        az_raw = az_raw[rows, _per_packet(tables.fill, dual)]
    return az_raw, wraps


def _decode(
    data: NDArray[np.uint8], host_stamp_ns: ArrayLike, model_hint: str | None = None
) -> _Decoded:
    arr = _check_packets(data)
    n = arr.shape[0]
    host = np.asarray(host_stamp_ns, dtype=np.int64).reshape(-1)
    if host.shape != (n,):
        raise DecodeError(f"{host.size} host stamps for {n} Velodyne packets")
    if n == 0:
        raise DecodeError("no Velodyne packets to detect a model from")
    fields = _fields(arr)
    id_model = _first_packet_model(fields)
    rmode = _return_modes(fields, id_model)
    model = _resolve_model(fields, rmode, id_model, model_hint)
    dual = rmode == RETURN_DUAL
    tables = _mode_tables(model)
    _check_flags(fields, model, tables, dual)
    az_raw, wraps = _azimuth_raw(fields, tables, dual)
    toh = _toh_us(fields)
    if toh.max() >= HOUR_US:
        i = int(np.argmax(toh >= HOUR_US))
        raise DecodeError(f"packet {i}: time stamp {int(toh[i])} us is past the hour")
    sensor_ns = resolve_hour_ns(toh, host)
    timing = PacketTiming(
        vendor="velodyne",
        model=model,
        sensor_time_ns=sensor_ns,
        block_azimuth_deg=az_raw / 100.0,
        block_time_ns=sensor_ns[:, None] + _per_packet(tables.block_offset_ns, dual),
        return_mode=rmode,
        dual_return=dual,
        wrap_blocks=wraps,
        product_id_model="" if model == id_model else id_model,
    )
    return _Decoded(timing, az_raw, dual.astype(np.intp))


def decode_velodyne(
    data: NDArray[np.uint8], host_stamp_ns: ArrayLike, model: str | None = None
) -> PacketTiming:
    """Decode n Velodyne packets (n, 1206) into per-packet and per-block timing.

    `host_stamp_ns` (n,) resolves the hour of the microseconds-past-the-hour stamp (see
    `resolve_hour_ns`). `model` is the rig's statement, else the product byte decides (and
    the packet cadence where the byte is 0x21, which early VLP-16s also wrote). Raises
    DecodeError on bytes that do not match the model.
    """
    return _decode(data, host_stamp_ns, model).timing


def velodyne_fov_gaps(timing: PacketTiming) -> NDArray[np.bool_]:
    """(n, 12) True for blocks after an azimuth jump inside their packet.

    A sensor with a restricted field of view (e.g. 270 -> 90 deg) fills the packet that
    crosses the FOV end with blocks of the next sweep: they were fired a whole gap later
    than the timing table says (the packet's stamp is its first block). Their
    `block_time_ns` is then wrong by that gap; drop them from time/azimuth fits.
    """
    layouts = (_layout(timing.model, False), _layout(timing.model, True))
    di = timing.dual_return.astype(np.intp)
    prv = np.stack([lay.prev_block for lay in layouts])[di]
    span = np.array([lay.span_ns for lay in layouts], dtype=np.float64)[di]
    max_gap_deg = (MAX_RPM * 6.0 * span / 1e9)[:, None]
    az = timing.block_azimuth_deg
    rows = np.arange(az.shape[0])[:, None]
    step = np.mod(az - az[rows, np.maximum(prv, 0)], 360.0)
    jump = (prv >= 0) & (step > max_gap_deg)
    flagged: NDArray[np.bool_] = np.logical_or.accumulate(jump, axis=1)
    return flagged


@dataclass(frozen=True, slots=True)
class VelodyneFirings:
    """Every record of n packets, (n, 12, 32): which laser fired, when, and where it pointed."""

    timing: PacketTiming
    laser_id: NDArray[np.int16]
    """Laser id in packet data order (VLS-128: 0..127, HDL-64E: upper 0..31, lower 32..63)."""
    sequence: NDArray[np.int16]
    """Firing sequence index within the packet (dual-return pairs share one)."""
    azimuth_deg: NDArray[np.float64]
    """Interpolated rotor azimuth at the firing, [0, 360), vendor convention."""
    time_ns: NDArray[np.int64]
    """Exact firing time, full epoch, sensor clock."""
    distance_m: NDArray[np.float64]
    """Measured distance, 0 where there was no return."""
    intensity: NDArray[np.uint8]
    """Calibrated reflectivity byte."""


def _gap_raw(
    az_raw: NDArray[np.int64],
    nxt: NDArray[np.intp],
    prv: NDArray[np.intp],
    max_gap: NDArray[np.float64],
    span_per_packet: NDArray[np.float64],
) -> NDArray[np.float64]:
    """(n, 12) azimuth advance (hundredths) from each block to its bank's next sample.

    The next sample in the packet if plausible, else the previous gap (the manual's rule
    for the last block), else the advance of the same block from packet to packet scaled
    to one span (VLS-128 dual has one sequence per packet), else 0. Gaps wider than
    `max_gap` (a FOV cut, a lost packet) are not rotation and are skipped.
    """
    rows = np.arange(az_raw.shape[0])[:, None]
    gap_next = (az_raw[rows, np.maximum(nxt, 0)] - az_raw) % 36000
    gap_prev = (az_raw - az_raw[rows, np.maximum(prv, 0)]) % 36000
    ok_next = (nxt >= 0) & (gap_next <= max_gap)
    ok_prev = (prv >= 0) & (gap_prev <= max_gap)
    across_next = np.zeros(az_raw.shape, dtype=np.float64)
    across_prev = np.zeros(az_raw.shape, dtype=np.float64)
    ok_across_next = np.zeros(az_raw.shape, dtype=bool)
    ok_across_prev = np.zeros(az_raw.shape, dtype=bool)
    if az_raw.shape[0] > 1:
        step = ((az_raw[1:] - az_raw[:-1]) % 36000) * span_per_packet[:-1]
        across_next[:-1] = step
        across_prev[1:] = step
        ok_across_next[:-1] = step <= max_gap[:-1]
        ok_across_prev[1:] = step <= max_gap[1:]
    gap = np.where(
        ok_next,
        gap_next,
        np.where(
            ok_prev,
            gap_prev,
            np.where(ok_across_next, across_next, np.where(ok_across_prev, across_prev, 0)),
        ),
    )
    return gap.astype(np.float64)


def velodyne_firing_times(
    data: NDArray[np.uint8], host_stamp_ns: ArrayLike, model: str | None = None
) -> VelodyneFirings:
    """Per record (packet, block, record): laser id, precision azimuth and exact firing time.

    Azimuth: block azimuth + gap * (time since the block's azimuth sample) / span, the
    manual's interpolation; the gap is to the next azimuth sample of the same bank (the
    last block reuses the previous gap). Time: stamp + the manual's timing offset.
    """
    arr = _check_packets(data)
    dec = _decode(arr, host_stamp_ns, model)
    timing = dec.timing
    layouts = (_layout(timing.model, False), _layout(timing.model, True))
    di = dec.dual_index
    nxt = np.stack([lay.next_block for lay in layouts])[di]
    prv = np.stack([lay.prev_block for lay in layouts])[di]
    span = np.array([lay.span_ns for lay in layouts], dtype=np.float64)[di]
    packet_ns = np.array([lay.packet_ns for lay in layouts], dtype=np.float64)[di]
    max_gap = (MAX_RPM * 6.0 * 100.0 * span / 1e9)[:, None]
    gap = _gap_raw(dec.azimuth_raw, nxt, prv, max_gap, (span / packet_ns)[:, None])
    since = np.stack([lay.since_azimuth_ns for lay in layouts])[di]
    frac = since / span[:, None, None]
    az = (dec.azimuth_raw[:, :, None] + gap[:, :, None] * frac) / 100.0
    az = np.mod(az, 360.0)
    firing = np.stack([lay.firing_ns for lay in layouts])[di]
    time_ns = timing.sensor_time_ns[:, None, None] + firing
    records = arr[:, :TOH_OFFSET].reshape(-1, BLOCKS, BLOCK_BYTES)[:, :, 4:]
    records = records.reshape(-1, BLOCKS, RECORDS, 3)
    dist_raw = records[..., 0].astype(np.int64) | (records[..., 1].astype(np.int64) << 8)
    laser = np.stack([lay.laser_id for lay in layouts])[di]
    return VelodyneFirings(
        timing=timing,
        laser_id=laser,
        sequence=np.stack([lay.sequence for lay in layouts])[di],
        azimuth_deg=az.astype(np.float64),
        time_ns=time_ns.astype(np.int64),
        distance_m=(dist_raw * DISTANCE_RESOLUTION_M[timing.model]).astype(np.float64),
        intensity=records[..., 2].copy(),
    )
