"""Which packet topics of a log hold LiDAR data: the one guess `info` and `audit` share.

A topic's message type says it carries raw packets (`stream.SCAN_TYPES`), not which: an
Ouster driver publishes its IMU packets with the same `PacketMsg` type as its LiDAR
packets (`/os_node0/imu_packets` beside `/os_node0/lidar_packets`). A packet topic is set
aside when its name says IMU, or, for Ouster, when its first packet is not the size the
sensor metadata gives for a LiDAR data packet (an IMU packet is 48 bytes).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, cast

from syncaudit.errors import SyncauditError
from syncaudit.lidar import ouster
from syncaudit.lidar.stream import SCAN_TYPES, find_ouster_metadata_topic, read_ouster_metadata
from syncaudit.logs import LogReader

_IMU_NAMES = ("imu_packets", "imu_packet")


@dataclass(frozen=True, slots=True)
class LidarTopicGuess:
    """The LiDAR packet topics of a log, best first, and the packet topics set aside."""

    topics: list[str] = field(default_factory=list)
    set_aside: dict[str, str] = field(default_factory=dict)
    """Packet topic -> why it is not LiDAR data."""

    @property
    def notes(self) -> list[str]:
        """One line per packet topic set aside, for a report's warnings."""
        return [
            f"{topic}: no LiDAR data packets, set aside ({why})"
            for topic, why in self.set_aside.items()
        ]


def guess_lidar_topics(log: LogReader) -> LidarTopicGuess:
    """The log's LiDAR data packet topics (sorted by name), without IMU packet topics."""
    guess = LidarTopicGuess()
    for topic in sorted(t.name for t in log.topics.values() if t.msgtype in SCAN_TYPES):
        why = _not_lidar(log, topic)
        if why is None:
            guess.topics.append(topic)
        else:
            guess.set_aside[topic] = why
    return guess


def guess_lidar_topic(log: LogReader) -> str | None:
    """The LiDAR data packet topic an audit without a rig uses (the first by name)."""
    topics = guess_lidar_topics(log).topics
    return topics[0] if topics else None


def _not_lidar(log: LogReader, topic: str) -> str | None:
    """Why a packet topic is not LiDAR data, or None when it is (or cannot be told)."""
    leaf = topic.rsplit("/", 1)[-1].lower()
    if leaf in _IMU_NAMES:
        return f"its name says IMU packets ({leaf})"
    if SCAN_TYPES[log.topics[topic].msgtype] != "ouster":
        return None
    meta_topic = find_ouster_metadata_topic(log, topic)
    if meta_topic is None:
        return None
    try:
        meta = read_ouster_metadata(log, meta_topic)
        first = next(iter(log.messages([topic])), None)
        if first is None:
            return None
        encoding = cast(Literal["ros1", "cdr"], first.encoding)
        size = int(ouster.ouster_packet_bytes(first.data, encoding).size)
    except SyncauditError:
        return None  # the scan itself reports what is wrong
    if size != meta.packet_bytes:
        return (
            f"its packets are {size} bytes, a LiDAR data packet is {meta.packet_bytes} "
            f"({meta_topic})"
        )
    return None
