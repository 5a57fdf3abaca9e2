"""ROS 1 `.bag` files read by our own reader: chunk units, a scan for bags without an index."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from syncaudit.errors import LogOpenError, LogReadError
from syncaudit.logs.base import LogReader
from syncaudit.logs.model import ChannelInfo, LogSummary, RawMessage, ReadUnit, TopicInfo
from syncaudit.logs.ros1.format import (
    MAGIC,
    UNIT_KIND,
    BagCutError,
    BagEncryptedError,
    BagFile,
    BagFormatError,
    BagIndex,
    Rosbag1ChunkReader,
    open_bag_file,
    read_bag_header,
    read_index,
    scan_chunks,
)
from syncaudit.logs.typesys import Definition, one_line
from syncaudit.logs.unit_merge import UnitMessage, merge_units, sorted_unit

if TYPE_CHECKING:
    pass


class Rosbag1Log(LogReader):
    """A ROS 1 bag (format 2.0): chunk-parallel units from its index, or from a chunk scan."""

    def __init__(self, path: Path, bag: BagFile | None = None) -> None:
        """Open the bag at `path`, or read its index from `bag` (over any seekable file
        object, such as a `remote.file.RemoteFile`: left open) and name it by `path`."""
        self.path = path
        self.warnings = []
        self._fallback = ""
        """Why the index was not used ('' where it was)."""
        if bag is not None:
            self._index = self._load(bag)
        else:
            try:
                bag = open_bag_file(path)
            except OSError as exc:
                raise LogOpenError(f"{path}: cannot read: {one_line(exc)}") from exc
            try:
                self._index = self._load(bag)
            finally:
                bag.handle.close()
        self.summary = self._make_summary()
        self._report_damage()
        self._chunk_reader = Rosbag1ChunkReader()

    def _load(self, bag: BagFile) -> BagIndex:
        """The index if it is whole, else a scan of the chunks (with the reason kept)."""

        if bag.read(0, len(MAGIC)) != MAGIC:
            raise LogOpenError(f"{self.path}: not a ROS 1 bag of format 2.0 (no '#ROSBAG V2.0')")
        try:
            index_pos, conn_count, chunk_count, first = read_bag_header(bag)
        except BagEncryptedError as exc:
            raise LogOpenError(
                f"{self.path}: ROS 1 bag is encrypted with {exc.problem}; encrypted bags are not "
                "supported (decrypt it with `rosbag decrypt` first)"
            ) from None
        except BagCutError:
            raise LogReadError(
                f"{self.path}: ROS 1 bag cut off at byte {bag.size} inside its bag header "
                "record; no message can be read"
            ) from None
        except BagFormatError as exc:
            raise LogReadError(f"{self.path}: ROS 1 bag header unreadable: {exc}") from None
        if first > bag.size:
            raise LogReadError(
                f"{self.path}: ROS 1 bag cut off at byte {bag.size} inside its bag header "
                "record; no message can be read"
            )
        if index_pos == 0:
            return self._scan(bag, first, "it has no index (the recording was not closed)")
        if index_pos < first:
            return self._scan(bag, first, f"its index position {index_pos} is inside its header")
        if index_pos >= bag.size:
            index = self._scan(bag, first, f"its index at byte {index_pos} is past the end")
            if index.cut_at is None:
                index.cut_at = bag.size  # cut at a record boundary before the index
            return index
        try:
            return read_index(bag, index_pos, conn_count, chunk_count)
        except BagCutError as exc:
            index = self._scan(bag, first, f"its index is cut off ({one_line(exc)})")
            if index.cut_at is None:
                index.cut_at = bag.size  # cut inside the index section
            return index
        except BagFormatError as exc:
            return self._scan(bag, first, f"its index is damaged ({one_line(exc)})")

    def _scan(self, bag: BagFile, first: int, reason: str) -> BagIndex:
        """Scan the chunks, keeping why the index was not used."""
        self._fallback = reason
        return scan_chunks(bag, first)

    def _make_summary(self) -> LogSummary:
        chunks = self._index.chunks
        counts: dict[int, int] = {}
        for span in chunks:
            for conn_id, count in span.counts.items():
                counts[conn_id] = counts.get(conn_id, 0) + count
        total = sum(counts.values())
        summary = LogSummary(
            path=str(self.path),
            container="rosbag1",
            start_ns=min((c.start_ns for c in chunks if c.counts), default=None) if total else None,
            end_ns=max((c.end_ns for c in chunks if c.counts), default=None) if total else None,
            message_count=total,
        )
        for conn in sorted(self._index.connections.values(), key=lambda c: c.conn_id):
            prior = summary.topics.get(conn.topic)
            summary.topics[conn.topic] = TopicInfo(
                name=conn.topic,
                msgtype=prior.msgtype if prior is not None else conn.msgtype,
                encoding="ros1",
                count=counts.get(conn.conn_id, 0) + (prior.count or 0 if prior else 0),
                has_definition=bool(conn.definition) or bool(prior and prior.has_definition),
            )
            if prior is not None and prior.msgtype != conn.msgtype:
                self.warn(
                    "rosbag1-mixed-types",
                    f"{self.path}: topic {conn.topic} is recorded with types {prior.msgtype} "
                    f"and {conn.msgtype}; only {prior.msgtype} is reported",
                )
        unknown = {c for span in chunks for c in span.counts} - set(self._index.connections)
        if unknown:
            self.warn(
                "rosbag1-unknown-connection",
                f"{self.path}: messages of connection(s) {sorted(unknown)} have no connection "
                "record (their topic is unknown); they are left out",
            )
        return summary

    def _report_damage(self) -> None:
        index = self._index
        if index.damage is None and index.cut_at is None and not self._fallback:
            return
        total = self.summary.message_count or 0
        if index.cut_at is not None:
            text = (
                f"{self.path}: ROS 1 bag cut off at byte {index.cut_at} (recording "
                f"interrupted?); reading the {total} complete messages before the cut"
            )
            code = "rosbag1-truncated"
        elif index.damage is None:
            text = (
                f"{self.path}: ROS 1 bag read by scanning its chunks because {self._fallback}; "
                f"{total} messages found"
            )
            code = "rosbag1-no-index"
        else:
            text = (
                f"{self.path}: ROS 1 bag damaged ({index.damage}); reading the {total} "
                "complete messages before it"
            )
            code = "rosbag1-damaged"
        if total == 0 and (index.cut_at is not None or code == "rosbag1-damaged"):
            raise LogReadError(text.split("; reading")[0] + "; no complete message can be read")
        self.warn(code, text)

    # -- units -------------------------------------------------------------------------------

    def _conn_ids(self, topics: frozenset[str] | None) -> set[int]:
        return {
            c.conn_id
            for c in self._index.connections.values()
            if topics is None or c.topic in topics
        }

    def read_units(self, topics: frozenset[str]) -> list[ReadUnit] | None:
        """One unit per chunk holding a message of `topics`, in file order."""
        return self._units(self._conn_ids(topics))

    def _units(self, conn_ids: set[int]) -> list[ReadUnit]:
        return [
            ReadUnit(
                source=str(self.path),
                kind=UNIT_KIND,
                offset=span.offset,
                length=span.length,
                start_ns=span.start_ns,
                end_ns=span.end_ns,
                cost=span.compressed_bytes,
            )
            for span in sorted(self._index.chunks, key=lambda s: s.offset)
            if not conn_ids.isdisjoint(span.counts)
        ]

    def unit_channels(self, topics: frozenset[str]) -> dict[int, ChannelInfo]:
        """Connection id -> topic, type, 'ros1' for the connections of `topics`."""
        return self._channels(topics)

    def _channels(self, topics: frozenset[str] | None) -> dict[int, ChannelInfo]:
        out: dict[int, ChannelInfo] = {}
        for conn in self._index.connections.values():
            if topics is None or conn.topic in topics:
                msgtype = self.summary.topics[conn.topic].msgtype
                if msgtype == conn.msgtype:
                    out[conn.conn_id] = ChannelInfo(conn.topic, msgtype, "ros1")
        return out

    # -- serial reading ----------------------------------------------------------------------

    def _messages(
        self, topics: frozenset[str] | None, start_ns: int | None, stop_ns: int | None
    ) -> Iterator[RawMessage]:
        """Messages in (log time, chunk offset, index) order, chunks opened as time reaches them."""
        channels = self._channels(topics)
        if not channels:
            return
        units = [
            u
            for u in self._units(set(channels))
            if (start_ns is None or u.end_ns >= start_ns)
            and (stop_ns is None or u.start_ns < stop_ns)
        ]

        def read(unit: ReadUnit) -> Iterator[UnitMessage]:
            return sorted_unit(self._chunk_reader.messages(unit, channels))

        for t, conn_id, payload in merge_units(units, read):
            if start_ns is not None and t < start_ns:
                continue
            if stop_ns is not None and t >= stop_ns:
                continue
            info = channels[conn_id]
            yield RawMessage(info.topic, info.msgtype, t, payload, "ros1")

    def _definitions(self, encoding: str) -> Iterator[Definition]:
        """The bag's connection definitions (ROS 1 defaults under them, whatever is asked)."""
        for c in self._index.connections.values():
            yield Definition(c.msgtype, "msg", c.definition, f"definition of {c.msgtype!r}")

    def _ros1_types(self, encoding: str) -> bool:
        return True

    def _close(self) -> None:
        self._chunk_reader.close()
