"""A pcap / pcapng capture of LiDAR traffic read as a log: one topic per sensor stream.

The capture is streamed by byte ranges of records (`ReadUnit` kind 'pcap-range', about
UNIT_BYTES each, boundaries found by `records.sync_offset`), in worker processes where the
audit asks for them and in order in `messages()`: both read the same ranges the same way,
so they yield the same messages. Within a range, a stream's Velodyne or Hesai packets are
batched into scan messages of up to SCAN_PACKETS packets; Ouster, position and IMU packets
are one message each; the Ouster metadata JSON beside the capture (same stem, `.json`, or
the file given) is a std_msgs/String on the stream's `metadata` topic.

Opening reads the first DISCOVER_BYTES of records (which streams there are) and the last
range (where the capture ends, and whether it is cut): never the whole file.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

from syncaudit.errors import LogOpenError
from syncaudit.logs.base import LogReader
from syncaudit.logs.model import ChannelInfo, LogSummary, RawMessage, ReadUnit, TopicInfo
from syncaudit.logs.pcap import ros_messages as ros
from syncaudit.logs.pcap.clock_source import PositionClock, ouster_timestamp_mode
from syncaudit.logs.pcap.records import (
    CaptureFormat,
    Record,
    RecordStream,
    read_format,
    sync_offset,
)
from syncaudit.logs.pcap.sensors import (
    OUSTER_LIDAR_PORT,
    VELODYNE_POSITION_PORT,
    StreamKey,
    classify,
)
from syncaudit.logs.pcap.udp import LINK_TYPES, UdpDecoder

UNIT_BYTES = 16 * 1024 * 1024
"""Bytes of capture per read unit."""
DISCOVER_BYTES = 64 * 1024 * 1024
"""Bytes of records read at open to find the sensor streams (and, for a capture no larger,
count every topic's messages exactly)."""
SCAN_PACKETS = 128
"""Velodyne / Hesai packets per scan message (a VLP-16 sends ~75 per revolution at 600 RPM)."""
UNIT_KIND = "pcap-range"
TAIL_RECORDS = 256
"""Records read past a range's end, at most, to complete its fragmented datagrams."""

_TYPES = {
    "velodyne": ros.VELODYNE_SCAN,
    "hesai": ros.NEBULA_PACKETS,
    "ouster": ros.OUSTER_PACKET,
    "imu": ros.OUSTER_PACKET,
    "position": ros.BYTES,
}


def ouster_ports(metadata_text: str | None) -> set[int]:
    """The Ouster lidar port the metadata names (udp_port_lidar), and the default 7502."""
    ports = {OUSTER_LIDAR_PORT}
    if metadata_text:
        try:
            root = json.loads(metadata_text)
        except ValueError:
            return ports
        if isinstance(root, dict):
            for place in (root, root.get("config_params")):
                port = place.get("udp_port_lidar") if isinstance(place, dict) else None
                if isinstance(port, int) and 0 < port < 65536:
                    ports.add(port)
    return ports


@dataclass(slots=True)
class _Batches:
    """Scan messages being gathered per stream in one range."""

    stamps: dict[StreamKey, list[int]] = field(default_factory=dict)
    packets: dict[StreamKey, list[bytes]] = field(default_factory=dict)
    seq: int = 0

    def add(self, key: StreamKey, time_ns: int, payload: bytes) -> bytes | None:
        stamps = self.stamps.setdefault(key, [])
        packets = self.packets.setdefault(key, [])
        stamps.append(time_ns)
        packets.append(payload)
        return self.flush(key) if len(packets) >= SCAN_PACKETS else None

    def flush(self, key: StreamKey) -> bytes | None:
        stamps, packets = self.stamps.get(key), self.packets.get(key)
        if not stamps or not packets:
            return None
        build = ros.velodyne_scan if key.kind == "velodyne" else ros.nebula_packets
        frame = key.topic.rsplit("/", 1)[0].lstrip("/")
        raw = build(self.seq, frame, stamps, packets)
        self.seq += 1
        self.stamps[key], self.packets[key] = [], []
        return raw


@dataclass(slots=True)
class RangeMessages:
    """Messages of the streams in `wanted` from one byte range of a capture."""

    stream: RecordStream
    wanted: dict[StreamKey, int]
    """Stream -> channel id."""
    ouster: set[int]
    udp: UdpDecoder = field(default_factory=UdpDecoder)
    other: int = 0

    def messages(self, start: int, stop: int) -> Iterator[tuple[int, int, bytes]]:
        """(log time, channel id, serialized message) of the range, in capture order."""
        batches = _Batches()
        last: dict[StreamKey, int] = {}
        for record in self._records(start, stop):
            if record.link_type not in LINK_TYPES:
                self.udp.not_udp += 1
                continue
            dgram = self.udp.datagram(record.data, record.link_type, new=record.offset < stop)
            if dgram is None:
                continue
            kind = classify(dgram.port, dgram.payload, None)
            if kind == "other" and dgram.port in self.ouster:
                kind = "ouster"
            key = StreamKey(kind, dgram.source, dgram.port)
            cid = self.wanted.get(key)
            if cid is None:
                self.other += kind == "other"
                continue
            if kind in ("velodyne", "hesai"):
                last[key] = record.time_ns
                raw = batches.add(key, record.time_ns, dgram.payload)
                if raw is not None:
                    yield record.time_ns, cid, raw
            elif kind == "position":
                yield record.time_ns, cid, ros.bytes_msg(dgram.payload)
            else:
                yield record.time_ns, cid, ros.packet_msg(dgram.payload)
        self.udp.finish()
        for key in sorted(last, key=lambda k: last[k]):
            raw = batches.flush(key)
            if raw is not None:
                yield last[key], self.wanted[key], raw

    def _records(self, start: int, stop: int) -> Iterator[Record]:
        """The range's records, then those after it that complete its fragmented
        datagrams (at most TAIL_RECORDS; the next range skips their fragments)."""
        yield from self.stream.iter_range(start, stop)
        if not self.udp.awaiting:
            return
        for count, record in enumerate(self.stream.iter_range(stop, self.stream.size)):
            yield record
            if not self.udp.awaiting or count >= TAIL_RECORDS:
                return


def _channels(topics: dict[str, TopicInfo]) -> dict[int, ChannelInfo]:
    names = sorted(topics)
    return {cid: ChannelInfo(name, topics[name].msgtype, "ros1") for cid, name in enumerate(names)}


def key_of_topic(topic: str) -> StreamKey | None:
    """The stream a capture topic stands for (None: the metadata topic, or not ours)."""
    parts = topic.split("/")
    if len(parts) != 4 or parts[1] != "pcap":
        return None
    kind = {
        "velodyne_packets": "velodyne",
        "hesai_packets": "hesai",
        "lidar_packets": "ouster",
        "position_packets": "position",
        "imu_packets": "imu",
    }.get(parts[3])
    address, _, port = parts[2].rpartition("_")
    if kind is None or not port.isdigit():
        return None
    return StreamKey(kind, address.replace("_", "."), int(port))


class PcapRangeReader:
    """Reads 'pcap-range' units of one capture (a worker's reader, `logs.unit_readers`)."""

    def __init__(self, source: str) -> None:
        self.path = source
        self.handle: BinaryIO = open(source, "rb")  # noqa: SIM115 - closed by close()
        self.size = os.fstat(self.handle.fileno()).st_size
        self.fmt = read_format(self.handle, source, self.size)

    def messages(
        self, unit: ReadUnit, channels: dict[int, ChannelInfo]
    ) -> Iterator[tuple[int, int, int, bytes]]:
        """(log time, index in unit, channel id, payload) of the unit's wanted messages."""
        wanted = {}
        ouster = {OUSTER_LIDAR_PORT}
        for cid, info in channels.items():
            key = key_of_topic(info.topic)
            if key is not None:
                wanted[key] = cid
                if key.kind == "ouster":
                    ouster.add(key.port)
        stream = RecordStream(self.handle, self.path, self.size, _copy(self.fmt))
        reader = RangeMessages(stream, wanted, ouster)
        for index, (time_ns, cid, raw) in enumerate(
            reader.messages(unit.offset, unit.offset + unit.length)
        ):
            yield time_ns, index, cid, raw

    def close(self) -> None:
        """Close the file."""
        self.handle.close()


def _copy(fmt: CaptureFormat) -> CaptureFormat:
    return CaptureFormat(fmt.kind, fmt.endian, list(fmt.interfaces), fmt.first_record)


class PcapLog(LogReader):
    """A classic pcap or pcapng capture opened as a log of sensor streams."""

    def __init__(self, path: Path, lidar_metadata: Path | None = None) -> None:
        self.path = path
        self.warnings = []
        self._handle: BinaryIO = path.open("rb")
        try:
            self.size = os.fstat(self._handle.fileno()).st_size
            self.fmt = read_format(self._handle, str(path), self.size)
            self.metadata_text = self._metadata(lidar_metadata)
            self._ouster = ouster_ports(self.metadata_text)
            self._bounds = self._unit_bounds()
            self.unit_start_ns: list[int] = []
            self.summary = self._discover()
        except BaseException:
            self._handle.close()
            raise

    # ---- open ------------------------------------------------------------------------------

    def _metadata(self, given: Path | None) -> str | None:
        """The Ouster metadata JSON: the file given, else the one of the same stem."""
        candidate = given if given is not None else self.path.with_suffix(".json")
        if given is not None and not given.is_file():
            raise LogOpenError(f"{given}: no such metadata file")
        if not candidate.is_file():
            return None
        try:
            return candidate.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise LogOpenError(f"{candidate}: cannot read the metadata: {exc}") from None

    def _unit_bounds(self) -> list[int]:
        """Record boundaries every ~UNIT_BYTES, from the first record to the end."""
        bounds = [self.fmt.first_record]
        offset = self.fmt.first_record + UNIT_BYTES
        while offset < self.size:
            at = sync_offset(self._handle, self.fmt, self.size, offset)
            if at >= self.size:
                break
            if at > bounds[-1]:
                bounds.append(at)
            offset = max(offset + UNIT_BYTES, at + 1)
        bounds.append(self.size)
        return bounds

    def _stream(self) -> RecordStream:
        return RecordStream(self._handle, str(self.path), self.size, _copy(self.fmt))

    def _discover(self) -> LogSummary:
        """Streams from the first DISCOVER_BYTES, the end (and any cut) from the last range."""
        udp = UdpDecoder()
        clocks: dict[StreamKey, PositionClock] = {}
        counts: dict[StreamKey, int] = {}
        per_unit: dict[tuple[StreamKey, int], int] = {}
        first_ns: int | None = None
        stream = self._stream()
        stop = min(self.size, self.fmt.first_record + DISCOVER_BYTES)
        unit = 0
        for record in stream.iter_range(self.fmt.first_record, stop):
            first_ns = record.time_ns if first_ns is None else first_ns
            while record.offset >= self._bounds[unit + 1]:
                unit += 1
            key, payload = self._key(udp, record)
            if key is not None:
                counts[key] = counts.get(key, 0) + 1
                if key.kind == "position" and key.port == VELODYNE_POSITION_PORT:
                    clocks.setdefault(key, PositionClock()).add(payload)
                per_unit[key, unit] = per_unit.get((key, unit), 0) + 1
        whole = stop == self.size
        # pcapng interfaces described after the first packet: a range read from the middle
        # would not know them, so such a capture is read in order (no read units).
        self.serial = len(stream.fmt.interfaces) > len(self.fmt.interfaces)
        for start in self._bounds[:-1]:
            self.unit_start_ns.append(self._first_time(start, first_ns))
        tail = self._stream()
        last_ns = first_ns
        for record in tail.iter_range(self._bounds[-2], self.size):
            last_ns = record.time_ns
        if tail.cut_at is not None:
            self.warn(
                "truncated",
                f"capture cut at byte {tail.cut_at} of {self.size} (inside a record): read to the cut",
            )
        topics: dict[str, TopicInfo] = {}
        for key in sorted(counts, key=lambda k: k.topic):
            if key.kind == "other":
                continue
            count = None
            if whole:  # every record was seen: the messages each stream makes, exactly
                batched = key.kind in ("velodyne", "hesai")
                runs = (
                    [counts[key]]
                    if self.serial
                    else [n for (k, _u), n in per_unit.items() if k == key]
                )
                count = sum(-(-n // SCAN_PACKETS) if batched else n for n in runs)
            topics[key.topic] = TopicInfo(key.topic, _TYPES[key.kind], "ros1", count, False)
            if key.kind == "ouster" and self.metadata_text is not None:
                meta = key.topic.rsplit("/", 1)[0] + "/metadata"
                topics[meta] = TopicInfo(meta, ros.STRING, "ros1", 1, False)
        for key, clock in sorted(clocks.items(), key=lambda kv: kv[0].topic):
            self.warn("clock-source", f"{key.topic}: {clock.describe()}")
        if self.metadata_text is None and any(k.kind == "ouster" for k in counts):
            self.warn(
                "no-metadata",
                f"Ouster packets but no {self.path.with_suffix('.json').name} beside the "
                "capture: pass its sensor metadata with --lidar-metadata FILE",
            )
        mode = ouster_timestamp_mode(self.metadata_text)
        if mode is not None and any(k.kind == "ouster" for k in counts):
            self.warn("clock-source", f"Ouster metadata: timestamp_mode {mode}")
        other = sum(n for k, n in counts.items() if k.kind == "other")
        if other:
            self.warn("not-sensor", f"{other} UDP datagrams of no LiDAR stream (not read)")
        if udp.not_udp:
            self.warn("not-udp", f"{udp.not_udp} frames are not IPv4 UDP (not read)")
        kind = "pcapng" if self.fmt.kind == "pcapng" else "pcap"
        total = sum(t.count or 0 for t in topics.values()) if whole else None
        return LogSummary(str(self.path), kind, first_ns, last_ns, total, topics)

    def _key(self, udp: UdpDecoder, record: Record) -> tuple[StreamKey | None, bytes]:
        if record.link_type not in LINK_TYPES:
            return None, b""
        dgram = udp.datagram(record.data, record.link_type)
        if dgram is None:
            return None, b""
        kind = classify(dgram.port, dgram.payload, None)
        if kind == "other" and dgram.port in self._ouster:
            kind = "ouster"
        return StreamKey(kind, dgram.source, dgram.port), dgram.payload

    def _first_time(self, start: int, default: int | None) -> int:
        for record in self._stream().iter_range(start, self.size):
            return record.time_ns
        return default or 0

    # ---- reading ---------------------------------------------------------------------------

    def read_units(self, topics: frozenset[str]) -> list[ReadUnit] | None:
        """One unit per byte range of records (metadata is read by `messages()`); None for
        a pcapng capture describing interfaces after its first packet."""
        if self.serial:
            return None
        units = []
        for i, start in enumerate(self._bounds[:-1]):
            stop = self._bounds[i + 1]
            end_ns = self.unit_start_ns[i + 1] if i + 1 < len(self.unit_start_ns) else None
            begin = self.unit_start_ns[i]
            units.append(
                ReadUnit(
                    str(self.path), UNIT_KIND, start, stop - start, begin,
                    end_ns if end_ns is not None else (self.summary.end_ns or begin),
                    stop - start,
                )
            )  # fmt: skip
        return units

    def unit_channels(self, topics: frozenset[str]) -> dict[int, ChannelInfo]:
        """Channel ids of the wanted packet topics."""
        return {
            cid: info
            for cid, info in _channels(self.summary.topics).items()
            if info.topic in topics and key_of_topic(info.topic) is not None
        }

    def _messages(
        self, topics: frozenset[str] | None, start_ns: int | None, stop_ns: int | None
    ) -> Iterator[RawMessage]:
        wanted_topics = frozenset(self.summary.topics) if topics is None else topics
        channels = self.unit_channels(wanted_topics)
        start = self.summary.start_ns or 0
        in_window = (start_ns is None or start >= start_ns) and (stop_ns is None or start < stop_ns)
        for name in sorted(wanted_topics):
            topic = self.summary.topics.get(name)
            is_metadata = topic is not None and topic.msgtype == ros.STRING
            if is_metadata and in_window and self.metadata_text:
                text = ros.string_msg(self.metadata_text)
                yield RawMessage(name, ros.STRING, start, text, "ros1")
        if not channels:
            return
        wanted = {k: c for c, i in channels.items() if (k := key_of_topic(i.topic)) is not None}
        ports = self._ouster | {k.port for k in wanted if k.kind == "ouster"}
        bounds = [self._bounds[0], self._bounds[-1]] if self.serial else self._bounds
        for i, begin in enumerate(bounds[:-1]):
            reader = RangeMessages(self._stream(), wanted, ports)
            for time_ns, cid, raw in reader.messages(begin, bounds[i + 1]):
                if (start_ns is not None and time_ns < start_ns) or (
                    stop_ns is not None and time_ns >= stop_ns
                ):
                    continue
                channel = channels[cid]
                yield RawMessage(channel.topic, channel.msgtype, time_ns, raw, "ros1")

    def _close(self) -> None:
        self._handle.close()
