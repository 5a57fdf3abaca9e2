"""Velodyne encoders for the simulator and tests: real-format packets and VelodyneScan messages.

The inverse of `syncaudit.lidar.velodyne`: `velodyne_revolution_schedule` lays out one
revolution of packets on the model's firing clock, `encode_velodyne` writes the 1206-byte
packets and `build_velodyne_scan` serializes a `velodyne_msgs/VelodyneScan` as the ROS
drivers' middleware does. Decoders are also tested against the real recordings and the
manuals' tables, not only against this encoder.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from syncaudit.lidar.velodyne import (
    _CDR_PACKET_STRIDE,
    _ROS1_PACKET_STRIDE,
    BLOCK_BYTES,
    BLOCKS,
    DISTANCE_RESOLUTION_M,
    ENCODABLE_MODELS,
    HOUR_US,
    MODEL_PRODUCT_ID,
    PACKET_BYTES,
    PRODUCT_ID_OFFSET,
    RECORDS,
    RETURN_DUAL,
    RETURN_MODE_OFFSET,
    RETURN_MODES,
    RETURN_STRONGEST,
    TOH_OFFSET,
    _align4,
    _check_encoding,
    _Layout,
    _layout,
)

__all__ = [
    "VelodyneSchedule",
    "build_velodyne_scan",
    "encode_velodyne",
    "velodyne_revolution_schedule",
]


def build_velodyne_scan(
    stamp_ns: int,
    frame_id: str,
    packet_stamps_ns: ArrayLike,
    data: ArrayLike,
    encoding: str = "cdr",
    *,
    big_endian: bool = False,
    seq: int = 0,
) -> bytes:
    """Serialize a velodyne_msgs/VelodyneScan the way the ROS drivers' middleware does.

    CDR: encapsulation 0001 (0000 if `big_endian`), packets at a 4-aligned stride of 1216,
    the message padded to a multiple of 4 with zeros (as rosbag2 recordings hold it).
    ROS 1: little endian, `seq` in the header, packets at a stride of 1214.
    """
    _check_encoding(encoding)
    stamps = np.asarray(packet_stamps_ns, dtype=np.int64).reshape(-1)
    packets = np.asarray(data, dtype=np.uint8)
    if packets.ndim != 2 or packets.shape[1] != PACKET_BYTES:
        raise ValueError(f"data must be (n, {PACKET_BYTES}) uint8, not {packets.shape}")
    if packets.shape[0] != stamps.size:
        raise ValueError(f"{stamps.size} packet stamps for {packets.shape[0]} packets")
    n = stamps.size
    sec, nsec = np.divmod(stamps, 1_000_000_000)
    frame = frame_id.encode("utf-8")
    head_sec, head_nsec = divmod(int(stamp_ns), 1_000_000_000)
    if encoding == "ros1":
        if seq < 0 or head_sec < 0 or (n and int(sec.min()) < 0):
            raise ValueError("ROS 1 times and seq must be non-negative")
        head = np.array([seq, head_sec, head_nsec, len(frame)], dtype="<u4").tobytes()
        head += frame + np.array([n], dtype="<u4").tobytes()
        body = np.zeros((n, _ROS1_PACKET_STRIDE), dtype=np.uint8)
        body[:, 0:4] = sec.astype("<u4").view(np.uint8).reshape(n, 4)
        body[:, 4:8] = nsec.astype("<u4").view(np.uint8).reshape(n, 4)
        body[:, 8:] = packets
        return head + body.tobytes()
    e = ">" if big_endian else "<"
    head = (b"\x00\x00" if big_endian else b"\x00\x01") + b"\x00\x00"
    head += np.array([head_sec], dtype=e + "i4").tobytes()
    head += np.array([head_nsec, len(frame) + 1], dtype=e + "u4").tobytes() + frame + b"\x00"
    head += b"\x00" * (_align4(len(head) - 4) + 4 - len(head))
    head += np.array([n], dtype=e + "u4").tobytes()
    body = np.zeros((n, _CDR_PACKET_STRIDE), dtype=np.uint8)
    body[:, 0:4] = sec.astype(e + "i4").view(np.uint8).reshape(n, 4)
    body[:, 4:8] = nsec.astype(e + "u4").view(np.uint8).reshape(n, 4)
    body[:, 8 : 8 + PACKET_BYTES] = packets
    return head + body.tobytes()


@dataclass(frozen=True, slots=True)
class VelodyneSchedule:
    """Packets of one revolution: what the encoder writes and when the sensor fired them."""

    model: str
    rpm: float
    return_mode: int
    packet_stamp_ns: NDArray[np.int64]
    """(n,) exact sensor time of each packet's stamp, full epoch."""
    packet_toh_us: NDArray[np.int64]
    """(n,) the stamp field: whole microseconds past the hour (truncated)."""
    block_azimuth_deg: NDArray[np.float64]
    """(n, 12) azimuth field of each block: rotor azimuth at the block's sample, 0.01 deg."""


def _encoder_layout(model: str, return_mode: int) -> _Layout:
    if model not in ENCODABLE_MODELS:
        raise ValueError(f"cannot encode {model!r}; encodable: {ENCODABLE_MODELS}")
    if return_mode not in RETURN_MODES:
        raise ValueError(f"return mode 0x{return_mode:02X} is not 0x37, 0x38 or 0x39")
    if model == "VLS-128" and return_mode == RETURN_DUAL:
        raise ValueError("VLS-128 dual-return packets are not encoded (layout unverified)")
    return _layout(model, return_mode == RETURN_DUAL)


def velodyne_revolution_schedule(
    model: str,
    rpm: float,
    start_time_ns: int,
    *,
    start_azimuth_deg: float = 0.0,
    return_mode: int = RETURN_STRONGEST,
    n_packets: int | None = None,
) -> VelodyneSchedule:
    """Lay out the packets of one revolution at a constant `rpm`.

    `start_time_ns` is the first firing of the first packet (sensor clock, epoch ns), when
    the rotor is at `start_azimuth_deg`. Packets follow at the model's packet period; each
    block's azimuth is the rotor azimuth when its firing sequence starts, quantised to the
    packet's 0.01 deg. By default enough packets to cover 360 deg.
    """
    lay = _encoder_layout(model, return_mode)
    if not rpm > 0:
        raise ValueError(f"rpm must be positive, not {rpm}")
    deg_per_ns = rpm * 6.0 / 1e9
    if n_packets is None:
        n_packets = math.ceil(360.0 / (deg_per_ns * lay.packet_ns))
    first_firing = lay.firing_ns.min()
    packet_first = int(start_time_ns) + np.arange(n_packets, dtype=np.int64) * lay.packet_ns
    stamp = packet_first - first_firing
    sample_ns = (lay.firing_ns - lay.since_azimuth_ns)[:, 0] - first_firing
    t_rel = (packet_first - int(start_time_ns))[:, None] + sample_ns[None, :]
    raw = np.rint((start_azimuth_deg + deg_per_ns * t_rel) * 100.0).astype(np.int64) % 36000
    return VelodyneSchedule(
        model=model,
        rpm=float(rpm),
        return_mode=return_mode,
        packet_stamp_ns=stamp.astype(np.int64),
        packet_toh_us=(stamp // 1000) % HOUR_US,
        block_azimuth_deg=raw / 100.0,
    )


def encode_velodyne(
    model: str,
    block_azimuth_deg: ArrayLike,
    packet_toh_us: ArrayLike,
    return_mode: int = RETURN_STRONGEST,
    *,
    rng: np.random.Generator | None = None,
    distances_m: ArrayLike | None = None,
    intensities: ArrayLike | None = None,
) -> NDArray[np.uint8]:
    """Real-format packets (n, 1206): flags, azimuths, records, stamp and factory bytes.

    Distances (n, 12, 32) in metres (0 = no return) and intensities default to plausible
    random values from `rng` (seeded 0 if None): 1-80 m, 5 % dropouts; in dual mode the
    second block of a pair repeats the first return 80 % of the time (identical echoes).
    """
    lay = _encoder_layout(model, return_mode)
    az = np.asarray(block_azimuth_deg, dtype=np.float64)
    toh = np.asarray(packet_toh_us, dtype=np.int64).reshape(-1)
    n = toh.size
    if az.shape != (n, BLOCKS):
        raise ValueError(f"block_azimuth_deg must be ({n}, {BLOCKS}), not {az.shape}")
    if ((toh < 0) | (toh >= HOUR_US)).any():
        raise ValueError("packet_toh_us must be in [0, 3.6e9) microseconds")
    az_raw = np.rint(az * 100.0).astype(np.int64) % 36000
    dual = return_mode == RETURN_DUAL
    if dual and not np.array_equal(az_raw[:, 0::2], az_raw[:, 1::2]):
        raise ValueError("dual-return blocks come in pairs with the same azimuth")
    res = DISTANCE_RESOLUTION_M[model]
    gen = rng if rng is not None else np.random.default_rng(0)
    shape = (n, BLOCKS, RECORDS)
    if distances_m is None:
        dist = gen.uniform(1.0, 80.0, size=shape)
        dist[gen.random(shape) < 0.05] = 0.0
        if dual:
            pair_shape = dist[:, 0::2].shape
            second = np.where(
                gen.random(pair_shape) < 0.8, 1.0, gen.uniform(0.3, 1.0, size=pair_shape)
            )
            dist[:, 1::2] = dist[:, 0::2] * second
    else:
        dist = np.broadcast_to(np.asarray(distances_m, dtype=np.float64), shape)
    if intensities is None:
        inten = gen.integers(0, 101, size=shape).astype(np.uint8)
    else:
        inten = np.broadcast_to(np.asarray(intensities, dtype=np.uint8), shape)
    dist_raw = np.clip(np.rint(dist / res), 0, 0xFFFF).astype(np.int64)
    out = np.zeros((n, PACKET_BYTES), dtype=np.uint8)
    blocks = out[:, :TOH_OFFSET].reshape(n, BLOCKS, BLOCK_BYTES)
    flags = lay.flags.astype(np.int64)
    blocks[:, :, 0] = flags & 0xFF
    blocks[:, :, 1] = flags >> 8
    blocks[:, :, 2] = az_raw & 0xFF
    blocks[:, :, 3] = az_raw >> 8
    recs = blocks[:, :, 4:].reshape(n, BLOCKS, RECORDS, 3)
    recs[..., 0] = dist_raw & 0xFF
    recs[..., 1] = dist_raw >> 8
    recs[..., 2] = inten
    out[:, TOH_OFFSET : TOH_OFFSET + 4] = toh.astype("<u4").view(np.uint8).reshape(n, 4)
    out[:, RETURN_MODE_OFFSET] = return_mode
    out[:, PRODUCT_ID_OFFSET] = MODEL_PRODUCT_ID[model]
    return out
