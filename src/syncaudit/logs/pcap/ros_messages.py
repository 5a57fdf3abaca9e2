"""ROS 1 serialization of captured packets as the drivers record them, so a capture reads
like a bag: Velodyne packets as velodyne_msgs/VelodyneScan, Hesai as nebula_msgs/
NebulaPackets, Ouster as ouster_sensor_msgs/PacketMsg (one per packet), the metadata JSON as
std_msgs/String. Each packet's stamp is its capture time (the host's receive time)."""

from __future__ import annotations

import struct

VELODYNE_SCAN = "velodyne_msgs/msg/VelodyneScan"
NEBULA_PACKETS = "nebula_msgs/msg/NebulaPackets"
OUSTER_PACKET = "ouster_sensor_msgs/msg/PacketMsg"
STRING = "std_msgs/msg/String"
BYTES = "std_msgs/msg/UInt8MultiArray"
"""Velodyne position / Hesai GPS datagrams, one each (not a LiDAR packet type)."""


def _time(ns: int) -> bytes:
    sec, nsec = divmod(ns, 1_000_000_000)
    return struct.pack("<II", sec & 0xFFFFFFFF, nsec)


def _header(seq: int, stamp_ns: int, frame_id: str) -> bytes:
    frame = frame_id.encode()
    return struct.pack("<I", seq) + _time(stamp_ns) + struct.pack("<I", len(frame)) + frame


def velodyne_scan(seq: int, frame_id: str, stamps_ns: list[int], packets: list[bytes]) -> bytes:
    """A VelodyneScan: header stamped with the last packet, then (stamp, 1206 bytes) each."""
    parts = [_header(seq, stamps_ns[-1], frame_id), struct.pack("<I", len(packets))]
    for stamp, data in zip(stamps_ns, packets, strict=True):
        parts.append(_time(stamp))
        parts.append(data)
    return b"".join(parts)


def nebula_packets(seq: int, frame_id: str, stamps_ns: list[int], packets: list[bytes]) -> bytes:
    """A NebulaPackets: header, then (stamp, uint8[] data) per packet."""
    parts = [_header(seq, stamps_ns[-1], frame_id), struct.pack("<I", len(packets))]
    for stamp, data in zip(stamps_ns, packets, strict=True):
        parts.append(_time(stamp) + struct.pack("<I", len(data)))
        parts.append(data)
    return b"".join(parts)


def packet_msg(data: bytes) -> bytes:
    """A PacketMsg: the uint8[] buffer."""
    return struct.pack("<I", len(data)) + data


def string_msg(text: str) -> bytes:
    """A std_msgs/String."""
    raw = text.encode()
    return struct.pack("<I", len(raw)) + raw


def bytes_msg(data: bytes) -> bytes:
    """A std_msgs/UInt8MultiArray with no dimensions: the bytes."""
    return struct.pack("<III", 0, 0, len(data)) + data
