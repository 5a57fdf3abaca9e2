"""Which sensor stream a UDP datagram belongs to, by port and payload size and signature.

Velodyne: 1206-byte data packets whose first block flag is FF EE/DD/CC/BB (port 2368 by
default, any port), 512-byte position packets (port 8308). Hesai: packets starting with
the EE FF pre-header, or Pandar40P's 1262/1266-byte packets starting with the FF EE block
flag (ports 2368, 2369, 10110 by default, any port); 512-byte GPS packets on
10110. Ouster: lidar packets on 7502, IMU (48 bytes) on 7503; the metadata beside the
capture says the lidar packet size. Streams are kept apart by source address and port.
"""

from __future__ import annotations

from dataclasses import dataclass

VELODYNE_DATA_BYTES = 1206
VELODYNE_POSITION_BYTES = 512
VELODYNE_POSITION_PORT = 8308
VELODYNE_FLAGS = (b"\xff\xee", b"\xff\xdd", b"\xff\xcc", b"\xff\xbb")
HESAI_PRE_HEADER = b"\xee\xff"
HESAI_P40_BYTES = (1262, 1266)
"""Pandar40P packets: no pre-header, the 0xFFEE block flag first (with or without UDP tail)."""
HESAI_GPS_PORT = 10110
OUSTER_LIDAR_PORT = 7502
OUSTER_IMU_PORT = 7503
OUSTER_IMU_BYTES = 48

KINDS = ("velodyne", "hesai", "ouster", "position", "imu", "other")
"""'position' and 'imu' are set aside and counted; 'other' is traffic of no sensor."""


@dataclass(frozen=True, slots=True)
class StreamKey:
    """One sensor stream: what it is, who sent it and to which port."""

    kind: str
    source: str
    port: int

    @property
    def topic(self) -> str:
        """The topic the stream's messages appear on."""
        name = {
            "velodyne": "velodyne_packets",
            "hesai": "hesai_packets",
            "ouster": "lidar_packets",
            "position": "position_packets",
            "imu": "imu_packets",
            "other": "udp",
        }[self.kind]
        return f"/pcap/{self.source.replace('.', '_')}_{self.port}/{name}"


def classify(port: int, payload: bytes, ouster_lidar_bytes: int | None) -> str:
    """The kind of one datagram: a kind of KINDS."""
    size = len(payload)
    head = payload[:2]
    if size == VELODYNE_DATA_BYTES and head in VELODYNE_FLAGS:
        return "velodyne"
    if (head == HESAI_PRE_HEADER and size > 12) or (
        size in HESAI_P40_BYTES and head == b"\xff\xee"
    ):
        return "hesai"
    if port == OUSTER_LIDAR_PORT or (ouster_lidar_bytes is not None and size == ouster_lidar_bytes):
        return "ouster"
    if port == OUSTER_IMU_PORT and size == OUSTER_IMU_BYTES:
        return "imu"
    if size == VELODYNE_POSITION_BYTES and port in (VELODYNE_POSITION_PORT, HESAI_GPS_PORT):
        return "position"
    return "other"
