"""Stream a LiDAR topic of a log as decoded packet chunks, one chunk per scan message.

Scans are viewed as numpy arrays over the raw serialized bytes (no generic
deserialiser), decoded by the vendor module the message type and packets point to.
Single-packet topics (Ouster) are batched so numpy still works on arrays.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, Literal, cast

import numpy as np
from numpy.typing import NDArray

from syncaudit.errors import DecodeError, NoDataError, UnknownTypeError
from syncaudit.lidar import hesai, ouster, velodyne
from syncaudit.lidar.packets import PacketTiming
from syncaudit.logs import LogReader, RawMessage

SCAN_TYPES: dict[str, str] = {
    "velodyne_msgs/msg/VelodyneScan": "velodyne",
    "pandar_msgs/msg/PandarScan": "hesai",
    "nebula_msgs/msg/NebulaPackets": "nebula",
    "ouster_ros/msg/PacketMsg": "ouster",
    "ouster_sensor_msgs/msg/PacketMsg": "ouster",
}
"""Message types that carry raw LiDAR packets, and the vendor family they belong to."""

OUSTER_BATCH = 256
VELODYNE_PACKET_BYTES = 1206


@dataclass(frozen=True, slots=True)
class PacketChunk:
    """Decoded packets of one scan message (or one batch of single-packet messages)."""

    scan_index: int
    log_time_ns: NDArray[np.int64]
    """(n,) log time of the message each packet came in."""
    driver_stamp_ns: NDArray[np.int64]
    """(n,) per-packet driver stamp (checkpoint 242); the log time where there is none."""
    timing: PacketTiming


def is_packet_topic(msgtype: str) -> bool:
    """True for message types syncaudit decodes as LiDAR packets."""
    return msgtype in SCAN_TYPES


def find_ouster_metadata_topic(log: LogReader, packet_topic: str) -> str | None:
    """The std_msgs/String metadata topic next to an Ouster packet topic, if any."""
    namespace = packet_topic.rsplit("/", 1)[0]
    candidates = [
        t.name
        for t in log.topics.values()
        if t.msgtype == "std_msgs/msg/String" and "metadata" in t.name.rsplit("/", 1)[-1]
    ]
    same_ns = [c for c in candidates if c.rsplit("/", 1)[0] == namespace]
    preferred = same_ns or candidates
    return preferred[0] if preferred else None


def read_ouster_metadata(log: LogReader, topic: str) -> ouster.OusterMetadata:
    """Parse the first metadata message on `topic`."""
    for msg in log.messages([topic]):
        text = getattr(log.deserialize(msg), "data", "")
        return ouster.parse_ouster_metadata(str(text))
    raise NoDataError(f"Ouster metadata topic {topic} holds no message")


def iter_packet_chunks(
    log: LogReader,
    topic: str,
    start_ns: int | None = None,
    stop_ns: int | None = None,
    ouster_metadata_topic: str | None = None,
) -> Iterator[PacketChunk]:
    """Decode every packet on `topic` in log order, a scan (or batch) at a time."""
    family, meta = packet_family(log, topic, ouster_metadata_topic)
    messages = log.messages([topic], start_ns, stop_ns)
    if meta is not None:
        yield from _ouster_chunks(messages, meta)
        return
    for index, msg in enumerate(messages):
        chunk = decode_scan(family, msg, index)
        if chunk is not None:
            yield chunk


def packet_family(
    log: LogReader, topic: str, ouster_metadata_topic: str | None = None
) -> tuple[str, ouster.OusterMetadata | None]:
    """The vendor family of a LiDAR topic's packets, and for Ouster its sensor metadata
    (from `ouster_metadata_topic`, else the metadata topic found beside the packets).

    Raises NoDataError (no such topic, no Ouster metadata) or DecodeError (not a packet type).
    """
    info = log.topics.get(topic)
    if info is None:
        raise NoDataError(f"LiDAR topic {topic} is not in the log")
    family = SCAN_TYPES.get(info.msgtype)
    if family is None:
        raise DecodeError(f"{topic}: {info.msgtype} is not a LiDAR packet type syncaudit knows")
    if family != "ouster":
        return family, None
    meta_topic = ouster_metadata_topic or find_ouster_metadata_topic(log, topic)
    if meta_topic is None:
        raise NoDataError(f"{topic}: Ouster packets need the sensor metadata topic; none found")
    return family, read_ouster_metadata(log, meta_topic)


def decode_scan(
    family: str, msg: RawMessage, index: int, model: str | None = None
) -> PacketChunk | None:
    """Decode one multi-packet scan message (None when it holds no packet); `model` is
    the rig's statement of a Velodyne model (else the packets tell).

    Raises UnknownTypeError where the message encoding is not cdr/ros1.
    """
    _check_encoding(msg)
    if family == "velodyne":
        stamps, data = velodyne.velodyne_scan_packets(msg.data, msg.encoding)
        if stamps.size == 0:
            return None
        timing = velodyne.decode_velodyne(data, stamps, model)
    else:
        if family == "hesai":
            stamps, data, sizes = hesai.pandar_scan_packets(msg.data, msg.encoding)
        else:
            stamps, packets = hesai.nebula_packets(msg.data, msg.encoding)
            data, sizes = hesai.stack_packets(packets)
        if stamps.size == 0:
            return None
        if family == "nebula" and _looks_velodyne(data, sizes):
            timing = velodyne.decode_velodyne(data[:, :VELODYNE_PACKET_BYTES], stamps, model)
        else:
            timing = hesai.decode_hesai(data, sizes, stamps)
    log_time = np.full(stamps.size, msg.log_time_ns, dtype=np.int64)
    return PacketChunk(index, log_time, stamps.astype(np.int64), timing)


def _check_encoding(msg: RawMessage) -> None:
    """UnknownTypeError (exit 4) for a packet message not in cdr/ros1 (the decoders' two)."""
    if msg.encoding not in ("cdr", "ros1"):
        raise UnknownTypeError(
            f"{msg.topic}: message encoding {msg.encoding!r} is not ROS (cdr/ros1); "
            "cannot decode its LiDAR packets"
        )


def _looks_velodyne(data: NDArray[np.uint8], sizes: NDArray[np.integer[Any]]) -> bool:
    """Nebula packets can be Velodyne: 1206 bytes starting with the 0xFFEE block flag."""
    return bool(
        np.all(sizes == VELODYNE_PACKET_BYTES) and data[0, 0] == 0xFF and data[0, 1] == 0xEE
    )


def _ouster_chunks(
    messages: Iterator[RawMessage], meta: ouster.OusterMetadata
) -> Iterator[PacketChunk]:
    """Batch single-packet Ouster messages; packets of another size (IMU) are skipped, but
    where the metadata did not state the packet shape the first lidar-sized packet fits it
    (`ouster.fit_packet_size`)."""
    size = meta.packet_bytes
    buffers: list[NDArray[np.uint8]] = []
    times: list[int] = []
    index = 0
    for msg in messages:
        _check_encoding(msg)
        buf = ouster.ouster_packet_bytes(msg.data, cast(Literal["ros1", "cdr"], msg.encoding))
        if buf.size != size:
            fitted = None if buffers else ouster.fit_packet_size(meta, int(buf.size))
            if fitted is None:
                continue
            meta, size = fitted, fitted.packet_bytes
        buffers.append(buf)
        times.append(msg.log_time_ns)
        if len(buffers) == OUSTER_BATCH:
            yield _ouster_batch(buffers, times, meta, index)
            buffers, times, index = [], [], index + 1
    if buffers:
        yield _ouster_batch(buffers, times, meta, index)


def decode_ouster_message(msg: RawMessage, meta: ouster.OusterMetadata) -> PacketChunk | None:
    """Decode one single-packet Ouster message (None for other packet sizes, e.g. IMU)."""
    _check_encoding(msg)
    buf = ouster.ouster_packet_bytes(msg.data, cast(Literal["ros1", "cdr"], msg.encoding))
    fitted = ouster.fit_packet_size(meta, int(buf.size))
    if fitted is None:
        return None
    return _ouster_batch([buf], [msg.log_time_ns], fitted, 0)


def _ouster_batch(
    buffers: list[NDArray[np.uint8]], times: list[int], meta: ouster.OusterMetadata, index: int
) -> PacketChunk:
    data = np.stack(buffers)
    log_time = np.array(times, dtype=np.int64)
    return PacketChunk(index, log_time, log_time, ouster.decode_ouster(data, meta))
