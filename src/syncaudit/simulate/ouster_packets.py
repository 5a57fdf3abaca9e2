"""Simulated Ouster OS-1-64 lidar packets and their sensor metadata, written from the
firmware user manual's layouts (not through `lidar.ouster`, which reads what this writes).

LEGACY: per column a 16-byte header (u64 timestamp ns, u16 measurement id, u16 frame id,
u32 encoder count = measurement id x 90112 / columns), 12-byte pixels, u32 status
0xFFFFFFFF. RNG19_RFL8_SIG16_NIR16 (12-byte pixels) and RNG15_RFL8_NIR8 (4-byte pixels):
a 32-byte packet header (u16 packet type 1, u16 frame id, u24 init id, u40 serial), per
column a 12-byte header (u64 timestamp, u16 measurement id, u16 status bit 0 = valid), the
pixels, and a 32-byte footer. Little endian. Columns fire when the encoder reaches their
angle, 360 deg x measurement id / columns_per_frame, so a column's time follows from the
rotation rather than its azimuth from the time.
"""

from __future__ import annotations

import json
from typing import Final, Literal

import numpy as np
from numpy.typing import NDArray

OusterProfile = Literal["LEGACY", "RNG19_RFL8_SIG16_NIR16", "RNG15_RFL8_NIR8"]
PROFILES: Final[tuple[OusterProfile, ...]] = ("LEGACY", "RNG19_RFL8_SIG16_NIR16", "RNG15_RFL8_NIR8")
PIXEL_BYTES: Final[dict[str, int]] = {
    "LEGACY": 12,
    "RNG19_RFL8_SIG16_NIR16": 12,
    "RNG15_RFL8_NIR8": 4,
}
MODEL: Final = "OS-1-64"
PIXELS: Final = 64
COLUMNS_PER_PACKET: Final = 16
ENCODER_TICKS: Final = 90112
INIT_ID: Final = 4_242_424
SERIAL: Final = 992_000_000_123
LIDAR_MODES: Final[dict[float, str]] = {600.0: "1024x10", 1200.0: "1024x20"}
"""Rotation rate (RPM) -> lidar_mode the simulator writes."""


def columns_per_frame(rpm: float) -> int:
    """Columns per revolution of the lidar_mode for `rpm` (ValueError for other rates)."""
    mode = LIDAR_MODES.get(float(rpm))
    if mode is None:
        raise ValueError(f"an Ouster spins at 600 or 1200 RPM (lidar_mode), not {rpm}")
    return int(mode.split("x")[0])


def packet_bytes(profile: str) -> int:
    """Bytes of one lidar packet of `profile`."""
    if profile == "LEGACY":
        return COLUMNS_PER_PACKET * (16 + PIXELS * 12 + 4)
    return 64 + COLUMNS_PER_PACKET * (12 + PIXELS * PIXEL_BYTES[profile])


def metadata_json(profile: str, rpm: float) -> str:
    """The sensor metadata in the flat format of firmware 2.x's `get_metadata`."""
    altitudes = np.linspace(16.6, -16.6, PIXELS).round(3).tolist()
    azimuths = [(-3.1 if k % 4 < 2 else 3.1) * (1 if k % 2 else -1) for k in range(PIXELS)]
    cols = columns_per_frame(rpm)
    return json.dumps(
        {
            "prod_line": MODEL,
            "prod_sn": str(SERIAL),
            "build_rev": "v2.3.0",
            "initialization_id": INIT_ID,
            "lidar_mode": LIDAR_MODES[float(rpm)],
            "timestamp_mode": "TIME_FROM_PTP_1588",
            "data_format": {
                "columns_per_frame": cols,
                "columns_per_packet": COLUMNS_PER_PACKET,
                "pixels_per_column": PIXELS,
                "column_window": [0, cols - 1],
                "udp_profile_lidar": profile,
                "udp_profile_imu": "LEGACY",
            },
            "beam_altitude_angles": altitudes,
            "beam_azimuth_angles": azimuths,
            "lidar_origin_to_beam_origin_mm": 15.806,
            "udp_port_lidar": 7502,
            "udp_port_imu": 7503,
        }
    )


def encode_packets(
    profile: str,
    measurement_id: NDArray[np.int64],
    timestamp_ns: NDArray[np.int64],
    frame_id: NDArray[np.int64],
    cols_per_frame: int,
) -> NDArray[np.uint8]:
    """Packets (n, packet_bytes) with the given column headers and zero-range pixels."""
    n = frame_id.shape[0]
    size = packet_bytes(profile)
    out = np.zeros((n, size), dtype=np.uint8)
    if profile == "LEGACY":
        col_bytes, head = 16 + PIXELS * 12 + 4, 0
    else:
        col_bytes, head = 12 + PIXELS * PIXEL_BYTES[profile], 32
        out[:, 0:2] = _le(np.ones(n, dtype=np.int64), 2)
        out[:, 2:4] = _le(frame_id & 0xFFFF, 2)
        out[:, 4:7] = _le(np.full(n, INIT_ID, dtype=np.int64), 3)
        out[:, 7:12] = _le(np.full(n, SERIAL, dtype=np.int64), 5)
    for c in range(COLUMNS_PER_PACKET):
        at = head + c * col_bytes
        out[:, at : at + 8] = _le(timestamp_ns[:, c], 8)
        out[:, at + 8 : at + 10] = _le(measurement_id[:, c], 2)
        if profile == "LEGACY":
            out[:, at + 10 : at + 12] = _le(frame_id & 0xFFFF, 2)
            encoder = measurement_id[:, c] * (ENCODER_TICKS // cols_per_frame)
            out[:, at + 12 : at + 16] = _le(encoder, 4)
            out[:, at + col_bytes - 4 : at + col_bytes] = 0xFF
        else:
            out[:, at + 10] = 1  # status: valid
    return out


def _le(values: NDArray[np.int64], width: int) -> NDArray[np.uint8]:
    """(n, width) little-endian bytes of non-negative integers."""
    v = np.asarray(values, dtype=np.uint64)
    shifts = (8 * np.arange(width, dtype=np.uint64))[None, :]
    return ((v[:, None] >> shifts) & np.uint64(0xFF)).astype(np.uint8)


def packet_msg(payload: bytes, encoding: str) -> bytes:
    """A serialized ouster_sensor_msgs/PacketMsg (`uint8[] buf`), ROS 1 or CDR."""
    length = len(payload).to_bytes(4, "little")
    if encoding == "ros1":
        return length + payload
    body = b"\x00\x01\x00\x00" + length + payload
    return body + b"\x00" * (-len(body) % 4)
