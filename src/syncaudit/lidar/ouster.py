"""Ouster OS-series lidar packets: metadata, message framing, column timing, and an encoder.

An Ouster lidar packet holds `columns_per_packet` measurement columns; each column carries
its own 64-bit timestamp and a measurement id (the column's index in the frame). This module
turns packets into `PacketTiming` (one "block" per column) so the audit can interpolate when
the beam pointed at a camera.

Layouts (little endian, as documented by Ouster and checked against a real OS-0-128 bag):

* LEGACY: no packet header. Each column: 16-byte header (u64 timestamp, u16 measurement id,
  u16 frame id, u32 encoder count), `pixels_per_column` x 12-byte pixels, u32 status
  (0xFFFFFFFF when valid).
* eUDP profiles (RNG19_RFL8_SIG16_NIR16, RNG19_RFL8_SIG16_NIR16_DUAL, RNG15_RFL8_NIR8,
  FIVE_WORD_PIXEL, FUSA_RNG15_RFL8_NIR8_DUAL: every profile of firmware 2.x-3.x, pixel sizes
  as ouster-sdk's profile table and the sensor's packets give them): 32-byte packet header (u16 packet type, u16 frame id, u24 init id,
  u40 serial number, shot-limiting / thermal bytes), then per column a 12-byte header (u64
  timestamp, u16 measurement id, u16 status) and pixels of 12, 16, 4, 20 or 8 bytes, then a
  32-byte packet footer (FuSa: a CRC-64 in it). The FuSa header differs (ouster-sdk's
  packet_format): u8 packet type, u24 init id, u32 frame id, u40 serial number at byte 11. The real OS-1-128 FuSa capture checks the
  sizes: 32 + 16 x (12 + 128 x 8) + 32 = 16640 bytes.

Older metadata (firmware 1.x-2.0 tools) may lack `prod_line`, `data_format` or fields of it;
what the packets need is then derived (columns from `lidar_mode`, pixels from the `beam_*`
arrays, the model line from the beams' altitude span, the profile and columns per packet
from the packet size: `fit_packet_size`), each derivation noted in `OusterMetadata.notes`.

Azimuth convention: `block_azimuth_deg` is Ouster's *encoder angle*, 0 deg at the lidar frame's
+X axis (the connector side, where frames start) and growing with time. The sensor spins
clockwise seen from above, so the counter-clockwise lidar-frame angle of a column is
`(360 - azimuth) % 360` (Ouster's `theta_encoder = 2 pi (1 - encoder_count / 90112)`).
"""

from __future__ import annotations

import json
import re
import struct
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from syncaudit.errors import DecodeError
from syncaudit.lidar.packets import PacketTiming
from syncaudit.logs.wire import WireError, cdr_byte_order

ENCODER_TICKS_PER_REV = 90112
"""Encoder counts per revolution in LEGACY packets (azimuth = 360 * count / 90112)."""

LIDAR_PACKET_TYPE = 1
"""`packet_type` of lidar packets in the eUDP packet header."""

EPOCH_THRESHOLD_NS = 946_684_800 * 1_000_000_000
"""2000-01-01T00:00:00Z. No sensor runs for 30 years, so smaller times count from power-on."""

UDP_PROFILE_CODES: dict[str, int] = {
    "LEGACY": 1,
    "RNG19_RFL8_SIG16_NIR16_DUAL": 2,
    "RNG19_RFL8_SIG16_NIR16": 3,
    "RNG15_RFL8_NIR8": 4,
    "FIVE_WORD_PIXEL": 5,
    "FUSA_RNG15_RFL8_NIR8_DUAL": 6,
}
"""Ouster's `UDPProfileLidar` enum values; used as `PacketTiming.return_mode`."""

_PIXEL_BYTES: dict[str, int] = {
    "LEGACY": 12,
    "RNG19_RFL8_SIG16_NIR16_DUAL": 16,
    "RNG19_RFL8_SIG16_NIR16": 12,
    "RNG15_RFL8_NIR8": 4,
    "FIVE_WORD_PIXEL": 20,
    "FUSA_RNG15_RFL8_NIR8_DUAL": 8,
}

_DUAL_PROFILES = frozenset({"RNG19_RFL8_SIG16_NIR16_DUAL", "FUSA_RNG15_RFL8_NIR8_DUAL"})
_FUSA_PROFILES = frozenset({"FUSA_RNG15_RFL8_NIR8_DUAL"})
"""Profiles with the FuSa packet header: 8-bit packet type, 32-bit frame id."""
_COLUMNS_PER_PACKET_CHOICES = (16, 8, 4, 2, 1)
"""Columns per packet the sensor can be configured to (firmware 2.x-3.x), most common first."""
_FAMILY_BY_SPAN_DEG = ((60.0, "OS-0"), (25.0, "OS-1"), (0.0, "OS-2"))
"""Model line from the beams' altitude span: OS-0 ~90 deg, OS-1 ~45 deg (gradient beam
spacing ~28 deg), OS-2 ~22 deg."""
_EUDP_HEADER_BYTES = 32
_EUDP_FOOTER_BYTES = 32
_LEGACY_VALID = 0xFFFFFFFF
_LIDAR_MODE_RE = re.compile(r"^(\d+)x(\d+)$")

Encoding = Literal["ros1", "cdr"]


@dataclass(frozen=True, slots=True)
class OusterMetadata:
    """What packet timing needs from the sensor metadata JSON (legacy or nested format)."""

    lidar_mode: str
    """E.g. '512x10': columns per frame x rotations per second."""
    columns_per_frame: int
    columns_per_packet: int
    pixels_per_column: int
    column_window: tuple[int, int]
    """First and last (inclusive) measurement id the sensor fills; may wrap past 0."""
    rotation_rate_hz: int
    """Rotations per second from `lidar_mode`."""
    udp_profile_lidar: str
    """'LEGACY', 'RNG19_RFL8_SIG16_NIR16', 'RNG19_RFL8_SIG16_NIR16_DUAL', 'RNG15_RFL8_NIR8'..."""
    prod_line: str
    """Product line as the sensor writes it, e.g. 'OS-1-64', 'OS-0-128'."""
    prod_sn: str
    """Serial number ('' when absent)."""
    initialization_id: int | None
    """Init id of the sensor session (eUDP packets repeat it in their header)."""
    timestamp_mode: str | None
    """'TIME_FROM_INTERNAL_OSC', 'TIME_FROM_SYNC_PULSE_IN', 'TIME_FROM_PTP_1588' or None."""
    firmware_rev: str | None
    """`build_rev`, e.g. 'v2.3.0'."""
    beam_azimuth_angles_deg: tuple[float, ...]
    """Per-beam azimuth offset in degrees (added to the column's angle in the lidar frame)."""
    beam_altitude_angles_deg: tuple[float, ...]
    lidar_origin_to_beam_origin_mm: float
    notes: tuple[str, ...] = ()
    """What older metadata omitted and was derived (warned about by `info`/`audit`)."""
    stated_shape: bool = True
    """False where the profile and columns per packet were not in the metadata (defaults):
    `fit_packet_size` may then take them from the packets' size."""

    @property
    def rotation_rate_rpm(self) -> float:
        """Configured rotation speed in revolutions per minute."""
        return 60.0 * self.rotation_rate_hz

    @property
    def frame_period_ns(self) -> float:
        """Nominal duration of one revolution in nanoseconds."""
        return 1e9 / self.rotation_rate_hz

    @property
    def column_period_ns(self) -> float:
        """Nominal time between consecutive measurement columns in nanoseconds."""
        return self.frame_period_ns / self.columns_per_frame

    @property
    def is_legacy(self) -> bool:
        """True for the LEGACY packet layout (encoder counts, no packet header)."""
        return self.udp_profile_lidar == "LEGACY"

    @property
    def pixel_bytes(self) -> int:
        """Bytes per pixel (channel data block) of the UDP profile."""
        return _PIXEL_BYTES[self.udp_profile_lidar]

    @property
    def column_bytes(self) -> int:
        """Bytes per measurement column, header and status included."""
        header, footer = (16, 4) if self.is_legacy else (12, 0)
        return header + self.pixels_per_column * self.pixel_bytes + footer

    @property
    def packet_bytes(self) -> int:
        """Bytes of one lidar packet (the UDP payload, i.e. `PacketMsg.buf`)."""
        extra = 0 if self.is_legacy else _EUDP_HEADER_BYTES + _EUDP_FOOTER_BYTES
        return extra + self.columns_per_packet * self.column_bytes


@dataclass(frozen=True, slots=True)
class OusterColumns:
    """Every column header of n packets with c columns each, decoded."""

    timestamp_ns: NDArray[np.int64]
    """(n, c) column time stamp as sent, sensor clock (see `ouster_clock_is_epoch`)."""
    measurement_id: NDArray[np.int64]
    """(n, c) column index within the frame."""
    status: NDArray[np.uint32]
    """(n, c) raw column status word."""
    valid: NDArray[np.bool_]
    """(n, c) status bit 0 set: the column holds a measurement (False outside the window)."""
    azimuth_deg: NDArray[np.float64]
    """(n, c) encoder angle in [0, 360), NaN where not valid."""
    frame_id: NDArray[np.int64]
    """(n,) frame counter (packet header, or first column in LEGACY)."""
    packet_type: NDArray[np.int64]
    """(n,) eUDP packet type (1 = lidar); 0 for LEGACY, which has none."""
    init_id: NDArray[np.int64]
    """(n,) eUDP initialization id; 0 for LEGACY."""
    prod_sn: NDArray[np.int64]
    """(n,) eUDP serial number; 0 for LEGACY."""


# --------------------------------------------------------------------------- metadata


def _fail(message: str) -> DecodeError:
    return DecodeError(f"ouster metadata: {message}")


def _obj(value: Any, where: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise _fail(f"'{where}' must be an object")
    return value


def _int(d: dict[str, Any], key: str, where: str) -> int:
    value = d.get(key)
    if isinstance(value, bool) or not isinstance(value, int):
        raise _fail(f"'{where}.{key}' must be an integer, got {value!r:.40}")
    return value


def _str(d: dict[str, Any], key: str, where: str) -> str:
    value = d.get(key)
    if not isinstance(value, str):
        raise _fail(f"'{where}.{key}' must be a string, got {value!r:.40}")
    return value


def _opt_str(d: dict[str, Any], key: str, where: str) -> str | None:
    return None if d.get(key) is None else _str(d, key, where)


def _floats(d: dict[str, Any], key: str, where: str) -> tuple[float, ...]:
    value = d.get(key)
    if not isinstance(value, list) or not all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in value
    ):
        raise _fail(f"'{where}.{key}' must be a list of numbers")
    return tuple(float(v) for v in value)


def _number(d: dict[str, Any], key: str, where: str, default: float) -> float:
    value = d.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _fail(f"'{where}.{key}' must be a number, got {value!r:.40}")
    return float(value)


def _parse_lidar_mode(mode: str) -> tuple[int, int]:
    match = _LIDAR_MODE_RE.match(mode)
    if match is None:
        raise _fail(f"lidar_mode {mode!r:.40} is not '<columns>x<rate>'")
    return int(match.group(1)), int(match.group(2))


def _build_metadata(
    *,
    lidar_mode: str,
    fmt: dict[str, Any] | None,
    fmt_where: str,
    default_columns_per_packet: int,
    prod_line: str,
    prod_sn: str,
    initialization_id: int | None,
    timestamp_mode: str | None,
    firmware_rev: str | None,
    beams: dict[str, Any],
    beams_where: str,
) -> OusterMetadata:
    """Validate and assemble the fields common to both JSON formats."""
    mode_columns, rate_hz = _parse_lidar_mode(lidar_mode)
    azimuths = _floats(beams, "beam_azimuth_angles", beams_where)
    altitudes = _floats(beams, "beam_altitude_angles", beams_where)
    origin_mm = _number(beams, "lidar_origin_to_beam_origin_mm", beams_where, 0.0)
    notes: list[str] = []
    stated_shape = True
    if fmt is None:  # firmware < 2.0 sent no data_format: 16-column LEGACY packets
        columns_per_frame, columns_per_packet = mode_columns, default_columns_per_packet
        pixels, profile = len(altitudes), "LEGACY"
        window = (0, mode_columns - 1)
        stated_shape = False
        notes.append(
            f"no data_format: {columns_per_frame} columns from lidar_mode, {pixels} pixels from "
            "the beam arrays, LEGACY profile and 16 columns per packet unless the packets' "
            "size says otherwise"
        )
    else:
        columns_per_frame = _derived_int(fmt, "columns_per_frame", fmt_where, mode_columns, notes)
        stated_shape = "columns_per_packet" in fmt and "udp_profile_lidar" in fmt
        columns_per_packet = _derived_int(
            fmt, "columns_per_packet", fmt_where, default_columns_per_packet, notes
        )
        pixels = _derived_int(fmt, "pixels_per_column", fmt_where, len(altitudes), notes)
        profile = fmt.get("udp_profile_lidar", "LEGACY")
        if "udp_profile_lidar" not in fmt:
            notes.append(f"no {fmt_where}.udp_profile_lidar: LEGACY (firmware < 2.2 default)")
        raw_window = fmt.get("column_window", [0, columns_per_frame - 1])
        if (
            not isinstance(raw_window, list)
            or len(raw_window) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) for v in raw_window)
        ):
            raise _fail(f"'{fmt_where}.column_window' must be two integers")
        window = (int(raw_window[0]), int(raw_window[1]))
    if not isinstance(profile, str) or profile.upper() not in UDP_PROFILE_CODES:
        raise _fail(f"unsupported udp_profile_lidar {profile!r:.40}")
    profile = profile.upper()
    if rate_hz <= 0 or columns_per_frame <= 0 or mode_columns != columns_per_frame:
        raise _fail(
            f"lidar_mode {lidar_mode!r} disagrees with columns_per_frame {columns_per_frame}"
        )
    if ENCODER_TICKS_PER_REV % columns_per_frame != 0:
        raise _fail(f"columns_per_frame {columns_per_frame} does not divide 90112 encoder ticks")
    if not 0 < columns_per_packet <= columns_per_frame or pixels <= 0:
        raise _fail(f"bad packet shape: {columns_per_packet} columns x {pixels} pixels")
    if not all(0 <= w < columns_per_frame for w in window):
        raise _fail(f"column_window {window} outside 0..{columns_per_frame - 1}")
    if len(azimuths) != pixels or len(altitudes) != pixels:
        raise _fail(
            f"{len(azimuths)} azimuth / {len(altitudes)} altitude angles for {pixels} pixels"
        )
    if not prod_line:
        prod_line = _derived_prod_line(altitudes)
        notes.append(
            f"no prod_line: {prod_line} from {pixels} beams spanning "
            f"{max(altitudes) - min(altitudes):.1f} deg of altitude"
        )
    return OusterMetadata(
        lidar_mode=lidar_mode,
        columns_per_frame=columns_per_frame,
        columns_per_packet=columns_per_packet,
        pixels_per_column=pixels,
        column_window=window,
        rotation_rate_hz=rate_hz,
        udp_profile_lidar=profile,
        prod_line=prod_line,
        prod_sn=prod_sn,
        initialization_id=initialization_id,
        timestamp_mode=timestamp_mode,
        firmware_rev=firmware_rev,
        beam_azimuth_angles_deg=azimuths,
        beam_altitude_angles_deg=altitudes,
        lidar_origin_to_beam_origin_mm=origin_mm,
        notes=tuple(notes),
        stated_shape=stated_shape,
    )


def _derived_int(d: dict[str, Any], key: str, where: str, default: int, notes: list[str]) -> int:
    """`d[key]`, else `default` with a note saying so."""
    if key in d:
        return _int(d, key, where)
    notes.append(f"no {where}.{key}: {default} derived")
    return default


def _derived_prod_line(altitudes: tuple[float, ...]) -> str:
    """'OS-<0|1|2>-<beams>' from the beams' altitude span (metadata without prod_line)."""
    span = max(altitudes) - min(altitudes) if altitudes else 0.0
    family = next(name for floor, name in _FAMILY_BY_SPAN_DEG if span >= floor)
    return f"{family}-{len(altitudes)}"


def fit_packet_size(meta: OusterMetadata, size: int) -> OusterMetadata | None:
    """`meta` fitted to lidar packets of `size` bytes: itself when it fits, else (where the
    metadata did not state the shape) the first profile and columns per packet whose packet
    is `size` bytes, with a note; None when nothing fits (e.g. an IMU packet)."""
    if size == meta.packet_bytes:
        return meta
    if meta.stated_shape:
        return None
    for profile in UDP_PROFILE_CODES:
        for columns in _COLUMNS_PER_PACKET_CHOICES:
            if columns > meta.columns_per_frame:
                continue
            trial = replace(meta, udp_profile_lidar=profile, columns_per_packet=columns)
            if trial.packet_bytes == size:
                note = f"{size}-byte packets: profile {profile}, {columns} columns per packet"
                return replace(trial, notes=(*meta.notes, note), stated_shape=True)
    return None


def _sn(d: dict[str, Any], where: str) -> str:
    value = d.get("prod_sn", "")
    if isinstance(value, bool) or not isinstance(value, str | int):
        raise _fail(f"'{where}.prod_sn' must be a string")
    return str(value)


def _opt_int(d: dict[str, Any], key: str, where: str) -> int | None:
    return None if d.get(key) is None else _int(d, key, where)


def _parse_nested(root: dict[str, Any]) -> OusterMetadata:
    """Format written by ouster-sdk >= 0.10 / ouster-ros >= 0.8 (sensor_info, lidar_data_format)."""
    info = _obj(root.get("sensor_info", {}), "sensor_info")
    fmt = _obj(root.get("lidar_data_format"), "lidar_data_format")
    config = _obj(root.get("config_params", {}), "config_params")
    beams = _obj(root.get("beam_intrinsics"), "beam_intrinsics")
    if "lidar_mode" in config:
        lidar_mode = _str(config, "lidar_mode", "config_params")
    else:  # some writers drop config_params: rebuild the mode from the data format
        fps = _int(fmt, "fps", "lidar_data_format")
        lidar_mode = f"{_int(fmt, 'columns_per_frame', 'lidar_data_format')}x{fps}"
    return _build_metadata(
        lidar_mode=lidar_mode,
        fmt=fmt,
        fmt_where="lidar_data_format",
        default_columns_per_packet=16,
        prod_line=_opt_str(info, "prod_line", "sensor_info") or "",
        prod_sn=_sn(info, "sensor_info"),
        initialization_id=_opt_int(info, "initialization_id", "sensor_info"),
        timestamp_mode=_opt_str(config, "timestamp_mode", "config_params"),
        firmware_rev=_opt_str(info, "build_rev", "sensor_info"),
        beams=beams,
        beams_where="beam_intrinsics",
    )


def _parse_legacy(root: dict[str, Any]) -> OusterMetadata:
    """Flat format of older SDKs / ouster_ros (top-level lidar_mode, optional data_format)."""
    fmt = root.get("data_format")
    beams = root
    beams_where = "<root>"
    if "beam_azimuth_angles" not in root and "beam_intrinsics" in root:
        beams = _obj(root["beam_intrinsics"], "beam_intrinsics")
        beams_where = "beam_intrinsics"
    return _build_metadata(
        lidar_mode=_str(root, "lidar_mode", "<root>"),
        fmt=None if fmt is None else _obj(fmt, "data_format"),
        fmt_where="data_format",
        default_columns_per_packet=16,
        prod_line=_opt_str(root, "prod_line", "<root>") or "",
        prod_sn=_sn(root, "<root>"),
        initialization_id=_opt_int(root, "initialization_id", "<root>"),
        timestamp_mode=_opt_str(root, "timestamp_mode", "<root>"),
        firmware_rev=_opt_str(root, "build_rev", "<root>"),
        beams=beams,
        beams_where=beams_where,
    )


def parse_ouster_metadata(text: str | bytes) -> OusterMetadata:
    """Parse the sensor metadata JSON that ouster_ros publishes on `.../metadata`.

    Both the nested format (`sensor_info`, `lidar_data_format`, `config_params`,
    `beam_intrinsics`) and the legacy flat one (`lidar_mode`, `data_format`, `prod_line`,
    top-level beam angles) give the same `OusterMetadata`. Raises `DecodeError` otherwise.
    """
    try:
        root = json.loads(text)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise _fail(f"not JSON ({exc})".replace("\n", " ")) from None
    root = _obj(root, "<root>")
    if "lidar_data_format" in root:
        return _parse_nested(root)
    if "lidar_mode" in root:
        return _parse_legacy(root)
    raise _fail("neither 'lidar_data_format' (nested) nor 'lidar_mode' (legacy) present")


# --------------------------------------------------------------------------- message framing


def ouster_packet_bytes(
    raw: bytes | bytearray | memoryview | NDArray[np.uint8], encoding: Encoding
) -> NDArray[np.uint8]:
    """The `buf` of one serialized `ouster_ros/PacketMsg` / `ouster_sensor_msgs/msg/PacketMsg`.

    `encoding` is 'ros1' (u32 length + bytes) or 'cdr' (4-byte encapsulation header,
    u32 length + bytes). Returns a zero-copy uint8 view into `raw`.
    """
    view = (raw.data if isinstance(raw, np.ndarray) else memoryview(raw)).cast("B")
    size = view.nbytes
    if encoding == "ros1":
        start, order = 4, "<"
    elif encoding == "cdr":
        start = 8
        try:  # plain CDR only, as every reader of logs.wire accepts (PL_CDR is refused)
            order = cdr_byte_order(view)
        except WireError as exc:
            raise DecodeError(f"ouster PacketMsg: {exc}") from None
    else:
        raise DecodeError(f"ouster PacketMsg: unknown encoding {encoding!r}")
    if size < start:
        raise DecodeError(f"ouster PacketMsg: {size} bytes, too short for a length field")
    (length,) = struct.unpack(order + "I", bytes(view[start - 4 : start]))
    trailing = size - start - length
    # CDR writers may pad the message to a multiple of 4 bytes; ROS 1 never pads.
    allowed = 3 if encoding == "cdr" else 0
    if not 0 <= trailing <= allowed:
        raise DecodeError(
            f"ouster PacketMsg: buf length {length} does not fit a {size}-byte {encoding} message"
        )
    return np.frombuffer(view, dtype=np.uint8, count=length, offset=start)


def build_ouster_packet_msg(buf: bytes | NDArray[np.uint8], encoding: Encoding) -> bytes:
    """Serialize a `PacketMsg` (`uint8[] buf`) as 'ros1' or little-endian 'cdr' bytes."""
    payload = buf if isinstance(buf, bytes) else np.ascontiguousarray(buf, np.uint8).tobytes()
    length = struct.pack("<I", len(payload))
    if encoding == "ros1":
        return length + payload
    if encoding == "cdr":
        return b"\x00\x01\x00\x00" + length + payload
    raise ValueError(f"unknown encoding {encoding!r}")


# --------------------------------------------------------------------------- packet layout


def _column_dtype(meta: OusterMetadata) -> np.dtype[np.void]:
    pixels = ("pixels", f"V{meta.pixels_per_column * meta.pixel_bytes}")
    if meta.is_legacy:
        fields: list[tuple[str, str]] = [
            ("timestamp", "<u8"),
            ("measurement_id", "<u2"),
            ("frame_id", "<u2"),
            ("encoder", "<u4"),
            pixels,
            ("status", "<u4"),
        ]
    else:
        fields = [("timestamp", "<u8"), ("measurement_id", "<u2"), ("status", "<u2"), pixels]
    dtype: np.dtype[np.void] = np.dtype(fields)
    assert dtype.itemsize == meta.column_bytes
    return dtype


def ouster_packet_dtype(meta: OusterMetadata) -> np.dtype[np.void]:
    """Numpy structured dtype of one whole lidar packet for `meta`'s profile."""
    columns = ("columns", _column_dtype(meta), (meta.columns_per_packet,))
    if meta.is_legacy:
        dtype: np.dtype[np.void] = np.dtype([columns])
    elif meta.udp_profile_lidar in _FUSA_PROFILES:
        # FuSa header (ouster-sdk packet_format): u8 packet type, u24 init id, u32 frame id,
        # 3 reserved bytes, u40 serial number, then the same status bytes at 16..19.
        dtype = np.dtype(
            [
                ("packet_type", "u1"),
                ("init_id", "u1", (3,)),
                ("frame_id", "<u4"),
                ("reserved0", "V3"),
                ("prod_sn", "u1", (5,)),
                ("countdown_thermal_shutdown", "u1"),
                ("countdown_shot_limiting", "u1"),
                ("thermal_shutdown", "u1"),
                ("shot_limiting", "u1"),
                ("reserved1", "V12"),
                columns,
                ("footer", f"V{_EUDP_FOOTER_BYTES}"),
            ]
        )
    else:
        dtype = np.dtype(
            [
                ("packet_type", "<u2"),
                ("frame_id", "<u2"),
                ("init_id", "u1", (3,)),
                ("prod_sn", "u1", (5,)),
                ("reserved0", "V4"),
                ("countdown_thermal_shutdown", "u1"),
                ("countdown_shot_limiting", "u1"),
                ("thermal_shutdown", "u1"),
                ("shot_limiting", "u1"),
                ("reserved1", "V12"),
                columns,
                ("footer", f"V{_EUDP_FOOTER_BYTES}"),
            ]
        )
    assert dtype.itemsize == meta.packet_bytes
    return dtype


def _le_uint(parts: NDArray[np.uint8]) -> NDArray[np.int64]:
    """Little-endian unsigned integer from the last axis of a byte array."""
    weights = np.left_shift(np.int64(1), 8 * np.arange(parts.shape[-1], dtype=np.int64))
    value: NDArray[np.int64] = (parts.astype(np.int64) * weights).sum(axis=-1)
    return value


def _as_packets(data: NDArray[np.uint8], meta: OusterMetadata) -> NDArray[np.void]:
    array = np.asarray(data)
    if array.dtype != np.uint8:
        raise DecodeError(f"ouster packets must be uint8, got {array.dtype}")
    if array.ndim == 1:
        array = array[np.newaxis, :]
    if array.ndim != 2 or array.shape[1] != meta.packet_bytes:
        raise DecodeError(
            f"ouster {meta.udp_profile_lidar} packet of {meta.columns_per_packet}x"
            f"{meta.pixels_per_column} must be {meta.packet_bytes} bytes, got shape {array.shape}"
        )
    packets: NDArray[np.void] = np.ascontiguousarray(array).view(ouster_packet_dtype(meta))[:, 0]
    return packets


# --------------------------------------------------------------------------- decode


def decode_ouster_columns(data: NDArray[np.uint8], meta: OusterMetadata) -> OusterColumns:
    """Decode every column header of n packets, shape (n, packet_bytes) (or one packet, 1-D).

    Azimuth: LEGACY uses the encoder count, `360 * count / 90112`; eUDP profiles carry no
    encoder, so (as Ouster's SDK does) the angle follows from the measurement id,
    `360 * measurement_id / columns_per_frame`. Columns whose status bit 0 is clear get NaN.
    Raises `DecodeError` on a wrong packet size, a non-lidar eUDP packet, or a valid column
    whose measurement id or encoder count is out of range for `meta`.
    """
    packets = _as_packets(data, meta)
    cols = packets["columns"]
    timestamp_ns = cols["timestamp"].astype(np.int64)
    measurement_id = cols["measurement_id"].astype(np.int64)
    status = cols["status"].astype(np.uint32)
    valid = (status & 1).astype(bool)
    n = packets.shape[0]
    if meta.is_legacy:
        encoder = cols["encoder"].astype(np.int64)
        bad = valid & (encoder >= ENCODER_TICKS_PER_REV)
        angle = 360.0 * encoder / ENCODER_TICKS_PER_REV
        frame_id = cols["frame_id"][:, 0].astype(np.int64)
        zeros = np.zeros(n, dtype=np.int64)
        packet_type, init_id, prod_sn = zeros, zeros.copy(), zeros.copy()
    else:
        packet_type = packets["packet_type"].astype(np.int64)
        if np.any(packet_type != LIDAR_PACKET_TYPE):
            first = int(np.flatnonzero(packet_type != LIDAR_PACKET_TYPE)[0])
            raise DecodeError(
                f"ouster packet {first} has packet_type {packet_type[first]}, expected 1 (lidar)"
            )
        bad = np.zeros_like(valid)
        angle = 360.0 * measurement_id / meta.columns_per_frame
        frame_id = packets["frame_id"].astype(np.int64)
        init_id = _le_uint(packets["init_id"])
        prod_sn = _le_uint(packets["prod_sn"])
    bad |= valid & (measurement_id >= meta.columns_per_frame)
    if np.any(bad):
        p, c = (int(i[0]) for i in np.nonzero(bad))
        raise DecodeError(
            f"ouster packet {p} column {c}: measurement id {measurement_id[p, c]} or encoder"
            f" out of range for {meta.lidar_mode}"
        )
    azimuth_deg = np.where(valid, np.mod(angle, 360.0), np.nan)
    return OusterColumns(
        timestamp_ns=timestamp_ns,
        measurement_id=measurement_id,
        status=status,
        valid=valid,
        azimuth_deg=azimuth_deg,
        frame_id=frame_id,
        packet_type=packet_type,
        init_id=init_id,
        prod_sn=prod_sn,
    )


def timing_from_columns(columns: OusterColumns, meta: OusterMetadata) -> PacketTiming:
    """`PacketTiming` of decoded columns: one block per column.

    `sensor_time_ns` is the first valid column's time (column 0's when none is valid; such a
    packet shows up as all-NaN azimuths). `block_time_ns` keeps every column's time as sent,
    also for invalid columns; use `columns.valid` or the NaN azimuths to drop them.
    """
    n = columns.timestamp_ns.shape[0]
    first_valid = np.argmax(columns.valid, axis=1)  # 0 when no column is valid
    sensor_time_ns = columns.timestamp_ns[np.arange(n), first_valid]
    code = UDP_PROFILE_CODES[meta.udp_profile_lidar]
    return PacketTiming(
        notes=meta.notes,
        vendor="ouster",
        model=meta.prod_line,
        sensor_time_ns=sensor_time_ns.astype(np.int64),
        block_azimuth_deg=columns.azimuth_deg,
        block_time_ns=columns.timestamp_ns,
        return_mode=np.full(n, code, dtype=np.uint8),
        dual_return=np.full(n, meta.udp_profile_lidar in _DUAL_PROFILES, dtype=bool),
        motor_rpm=np.full(n, meta.rotation_rate_rpm, dtype=np.float64),
    )


def decode_ouster(data: NDArray[np.uint8], meta: OusterMetadata) -> PacketTiming:
    """Per-packet / per-column timing of n Ouster lidar packets, shape (n, packet_bytes).

    Times are the sensor clock as sent: with TIME_FROM_INTERNAL_OSC they count from power-on,
    not from the epoch (check with `ouster_clock_is_epoch`). `return_mode` is the UDP profile
    code (`UDP_PROFILE_CODES`); `dual_return` marks the DUAL profile, whose two returns share
    one column (columns do not repeat azimuths). Invalid columns have NaN azimuth; call
    `decode_ouster_columns` for the explicit mask.
    """
    return timing_from_columns(decode_ouster_columns(data, meta), meta)


def ouster_clock_is_epoch(sensor_time_ns: int | NDArray[np.int64]) -> bool:
    """True when the sensor times are Unix-epoch based (PTP, or sync pulse with NMEA).

    TIME_FROM_INTERNAL_OSC (the default) and an unsynchronised sync-pulse clock count from
    power-on, i.e. seconds to days, far below year 2000 in epoch nanoseconds. Note PTP time
    is TAI, 37 s ahead of UTC, unless the grandmaster says otherwise.
    """
    times = np.asarray(sensor_time_ns, dtype=np.int64)
    return bool(times.size > 0 and np.all(times >= EPOCH_THRESHOLD_NS))


# --------------------------------------------------------------------------- encode


def encode_ouster(
    meta: OusterMetadata,
    measurement_id: NDArray[np.integer[Any]],
    timestamp_ns: NDArray[np.integer[Any]],
    frame_id: NDArray[np.integer[Any]],
    valid: NDArray[np.bool_] | None = None,
) -> NDArray[np.uint8]:
    """Build n lidar packets (n, packet_bytes) with the given column headers and zero pixels.

    `measurement_id` and `timestamp_ns` are (n, columns_per_packet), `frame_id` (n,),
    `valid` (n, columns_per_packet) defaults to all True. LEGACY packets get the encoder
    count `measurement_id * 90112 / columns_per_frame`; eUDP packets get packet type 1 and
    the metadata's init id and serial number.
    """
    mid = np.asarray(measurement_id, dtype=np.int64)
    ts = np.asarray(timestamp_ns, dtype=np.int64)
    fid = np.asarray(frame_id, dtype=np.int64)
    n = fid.shape[0]
    shape = (n, meta.columns_per_packet)
    ok = np.ones(shape, dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
    if mid.shape != shape or ts.shape != shape or ok.shape != shape or fid.ndim != 1:
        raise ValueError(f"column arrays must be {shape} and frame_id ({n},)")
    if np.any((mid < 0) | (mid >= meta.columns_per_frame)) or np.any(ts < 0):
        raise ValueError("measurement ids must be in 0..columns_per_frame-1 and times >= 0")
    packets = np.zeros(n, dtype=ouster_packet_dtype(meta))
    cols = packets["columns"]
    cols["timestamp"] = ts.astype(np.uint64)
    cols["measurement_id"] = mid.astype(np.uint16)
    if meta.is_legacy:
        ticks_per_column = ENCODER_TICKS_PER_REV // meta.columns_per_frame
        cols["encoder"] = (mid * ticks_per_column).astype(np.uint32)
        cols["frame_id"] = (fid[:, np.newaxis] & 0xFFFF).astype(np.uint16)
        cols["status"] = np.where(ok, _LEGACY_VALID, 0).astype(np.uint32)
    else:
        packets["packet_type"] = LIDAR_PACKET_TYPE
        wide = meta.udp_profile_lidar in _FUSA_PROFILES
        packets["frame_id"] = fid & (0xFFFFFFFF if wide else 0xFFFF)
        init_id = meta.initialization_id or 0
        serial = int(meta.prod_sn) if meta.prod_sn.isdigit() else 0
        packets["init_id"] = np.frombuffer((init_id & 0xFFFFFF).to_bytes(3, "little"), np.uint8)
        packets["prod_sn"] = np.frombuffer((serial & (2**40 - 1)).to_bytes(5, "little"), np.uint8)
        cols["status"] = ok.astype(np.uint16)
    out: NDArray[np.uint8] = packets.view(np.uint8).reshape(n, meta.packet_bytes)
    return out
