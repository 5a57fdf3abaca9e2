"""MCAP files (ROS 1 and ROS 2 encodings) through the `mcap` package."""

from __future__ import annotations

import io
import struct
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import BinaryIO

from mcap.exceptions import McapError
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import StreamReader, breakup_chunk

from syncaudit.errors import LogOpenError, LogReadError
from syncaudit.logs.base import LogReader, selected
from syncaudit.logs.model import LogSummary, RawMessage, TopicInfo
from syncaudit.logs.typesys import TypeRegistry, normalise_type_name, parse_definition

_ENCODINGS = {"cdr": "cdr", "ros1": "ros1"}
# Errors the mcap package and its decompressors raise on damaged bytes.
_READ_ERRORS = (McapError, struct.error, ValueError, EOFError, OSError, RuntimeError)


class McapLog(LogReader):
    """An MCAP file; indexed reading when it has a summary, linear otherwise."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.warnings = []
        self._file: BinaryIO = path.open("rb")
        try:
            self._reader = SeekingReader(self._file)
        except _READ_ERRORS as exc:
            self._file.close()
            raise LogOpenError(f"{path}: not a readable MCAP file ({exc})") from exc
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._registries: dict[str, TypeRegistry] = {}
        self._indexed = self._load_summary()

    def _load_summary(self) -> bool:
        """Fill `summary` from the MCAP summary section, or by a linear scan without one."""
        try:
            summary = self._reader.get_summary()
        except _READ_ERRORS:
            summary = None
        if summary is not None and summary.chunk_indexes:
            self._schemas = dict(summary.schemas)
            self._channels = dict(summary.channels)
            stats = summary.statistics
            counts = stats.channel_message_counts if stats else {}
            self.summary = LogSummary(
                path=str(self.path),
                container="mcap",
                start_ns=stats.message_start_time if stats and stats.message_count else None,
                end_ns=stats.message_end_time if stats and stats.message_count else None,
                message_count=stats.message_count if stats else None,
            )
            for cid, channel in self._channels.items():
                self._add_topic(channel, counts.get(cid))
            return True
        self.warn(
            "mcap-no-summary",
            f"{self.path.name}: MCAP has no summary/index (recording cut off?); reading linearly",
        )
        self._scan_linear()
        return False

    def _add_topic(self, channel: Channel, count: int | None) -> None:
        schema = self._schemas.get(channel.schema_id)
        msgtype = normalise_type_name(schema.name) if schema else "<no schema>"
        prior = self.summary.topics.get(channel.topic)
        if prior is not None and count is not None and prior.count is not None:
            count += prior.count
        self.summary.topics[channel.topic] = TopicInfo(
            name=channel.topic,
            msgtype=msgtype,
            encoding=_ENCODINGS.get(channel.message_encoding, channel.message_encoding),
            count=count,
            has_definition=bool(schema and schema.data),
        )

    def _scan_linear(self) -> None:
        """Count messages per channel and their time range by reading every record."""
        counts: dict[int, int] = {}
        start: int | None = None
        end: int | None = None
        for message in self._linear_messages(None, None, None):
            counts[message.channel_id] = counts.get(message.channel_id, 0) + 1
            start = message.log_time if start is None else min(start, message.log_time)
            end = message.log_time if end is None else max(end, message.log_time)
        self.summary = LogSummary(
            path=str(self.path),
            container="mcap",
            start_ns=start,
            end_ns=end,
            message_count=sum(counts.values()),
        )
        for cid, channel in self._channels.items():
            self._add_topic(channel, counts.get(cid, 0))

    def _linear_messages(
        self, topics: frozenset[str] | None, start_ns: int | None, stop_ns: int | None
    ) -> Iterator[Message]:
        """Every message record in file order; stops with a warning where the file is cut."""
        self._file.seek(0, io.SEEK_SET)
        stream = StreamReader(self._file, skip_magic=False)
        try:
            for record in stream.records:
                records = breakup_chunk(record) if isinstance(record, Chunk) else [record]
                for rec in records:
                    if isinstance(rec, Schema):
                        self._schemas[rec.id] = rec
                    elif isinstance(rec, Channel):
                        self._channels[rec.id] = rec
                    elif isinstance(rec, Message):
                        if _wanted(rec, self._channels, topics, start_ns, stop_ns):
                            yield rec
        except _READ_ERRORS as exc:
            self.warn(
                "mcap-truncated",
                f"{self.path.name}: MCAP ends early or is damaged after offset "
                f"{self._file.tell()} ({type(exc).__name__}); using what was read before it",
            )

    def messages(
        self,
        topics: Iterable[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[RawMessage]:
        """Raw messages in log-time order (file order when the MCAP has no index)."""
        wanted = selected(topics)
        if not self._indexed:
            for rec in self._linear_messages(wanted, start_ns, stop_ns):
                yield self._raw(self._channels[rec.channel_id], rec)
            return
        try:
            for _schema, channel, rec in self._reader.iter_messages(
                topics=None if wanted is None else sorted(wanted),
                start_time=start_ns,
                end_time=stop_ns,
                log_time_order=True,
            ):
                yield self._raw(channel, rec)
        except _READ_ERRORS as exc:
            raise LogReadError(
                f"{self.path.name}: corrupt MCAP data near offset {self._file.tell()} "
                f"({type(exc).__name__}: {exc})"
            ) from exc

    def _raw(self, channel: Channel, rec: Message) -> RawMessage:
        info = self.summary.topics.get(channel.topic)
        if info is None:
            self._add_topic(channel, None)
            info = self.summary.topics[channel.topic]
        return RawMessage(channel.topic, info.msgtype, rec.log_time, rec.data, info.encoding)

    def type_registry(self, encoding: str) -> TypeRegistry:
        """Types from this file's schemas of the given encoding, then schemas/ and ROS."""
        if encoding not in self._registries:
            ros1 = encoding == "ros1"
            log_types: dict[str, object] = {}
            for channel in self._channels.values():
                schema = self._schemas.get(channel.schema_id)
                if schema is None or not schema.data or (channel.message_encoding == "ros1") != ros1:
                    continue
                name = normalise_type_name(schema.name)
                try:
                    parsed = parse_definition(schema.encoding, schema.data.decode(), name)
                except Exception as exc:  # noqa: BLE001 - a bad schema must not stop the audit
                    self.warn("bad-schema", f"schema {schema.name!r} unreadable: {exc}")
                    continue
                log_types.update({k: v for k, v in parsed.items() if k not in log_types})
            self._registries[encoding] = TypeRegistry(ros1=ros1, log_types=log_types)
        return self._registries[encoding]

    def close(self) -> None:
        """Close the file."""
        self._file.close()


def _wanted(
    rec: Message,
    channels: dict[int, Channel],
    topics: frozenset[str] | None,
    start_ns: int | None,
    stop_ns: int | None,
) -> bool:
    channel = channels.get(rec.channel_id)
    if channel is None:
        return False
    if topics is not None and channel.topic not in topics:
        return False
    if start_ns is not None and rec.log_time < start_ns:
        return False
    return stop_ns is None or rec.log_time < stop_ns
