"""MCAP files (ROS 1 and ROS 2 encodings) through the `mcap` package.

Two ways of reading, chosen at open:

- indexed: the file ends with a footer whose summary holds chunk indexes (read with
  `mcap`'s `SeekingReader`); the chunks a query needs are read by our own `ChunkReader`
  (sizes bounded before allocating) and merged in log-time order, and they are the read
  units of the chunk-parallel path (`read_units`).
- linear: no usable summary (a recording that was cut off, a writer that skipped the
  summary, an unchunked file). One pass at open builds the topic table and a list of
  chunks with their time ranges; queries then read chunk by chunk, merged by log time,
  so memory stays at the chunks that overlap in time. A cut-off file yields every
  message that is complete before the cut, including those of a partly written chunk.

Malformed files are refused with one line naming the file and offset: a chunk whose
declared size is impossible or a bomb, a log time past int64, one channel id declared for
two topics (`mcap` would keep the last and silently lose the other topic).
"""

from __future__ import annotations

import heapq
import io
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Channel, Chunk, Message, Schema
from mcap.summary import Summary

from syncaudit.errors import LogOpenError, LogReadError, SyncauditError
from syncaudit.logs.base import LogReader
from syncaudit.logs.magic import MCAP_MAGIC
from syncaudit.logs.mcap.chunks import (
    MAX_CHUNK_BYTES,
    MAX_LOG_TIME_NS,
    RECORD_HEAD,
    ChunkReader,
    check_declared_size,
    chunk_where,
    decompress_bounded,
    decompress_upto,
    iter_chunk_messages,
)
from syncaudit.logs.model import ChannelInfo, LogSummary, RawMessage, ReadUnit, TopicInfo
from syncaudit.logs.typesys import (
    Definition,
    normalise_type_name,
    one_line,
)

if TYPE_CHECKING:
    pass

MAGIC = MCAP_MAGIC
HEADER_CHECKS = 4096
"""Chunk headers checked against their index at open (4096 chunks: ~16 GB of 4 MB chunks)."""
MAX_CHUNK_RECORD_BYTES = MAX_CHUNK_BYTES + MAX_CHUNK_BYTES // 64 + 2**20
"""Longest chunk record read whole: compressed data never much exceeds the records."""
_FOOTER = struct.Struct("<BQQQI")  # opcode, length, summary start, summary offset start, crc
_MESSAGE_INDEX_HEAD = struct.Struct("<BQHI")  # opcode, length, channel id, records bytes
_CHUNK_RECORD_HEAD = struct.Struct("<BQQQQ")  # opcode, length, start, end, uncompressed size


@dataclass(frozen=True, slots=True)
class _ChunkSpan:
    """A chunk found by the linear scan: where it is and what it holds."""

    offset: int
    length: int
    start_ns: int
    end_ns: int
    channels: frozenset[int]


@dataclass(slots=True)
class _Scan:
    """What one linear pass over an MCAP without index found."""

    chunks: list[_ChunkSpan] = field(default_factory=list)
    loose: bool = False
    """Some messages lie outside chunks (so chunk-wise reading cannot find them)."""
    ordered: bool = True
    """Messages appear in the file in non-decreasing log time."""


class McapLog(LogReader):
    """An MCAP file; indexed reading when it has a summary, linear otherwise."""

    def __init__(self, path: Path, file: BinaryIO | None = None) -> None:
        """Open the MCAP at `path`, or read `file` (a seekable file object, such as a
        `remote.file.RemoteFile`; closed with the log) and name it by `path`."""
        self.path = path
        self.warnings = []
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._cut: str | None = None
        self._scan = _Scan()
        if file is None:
            try:
                file = path.open("rb")
            except OSError as exc:
                raise LogOpenError(f"{path}: cannot open: {one_line(exc)}") from exc
        self._file: BinaryIO = file
        try:
            self._size = file.seek(0, io.SEEK_END)
            file.seek(0)
            self._reader = SeekingReader(self._file, validate_crcs=True)
            self._check_header()
            index = self._load_index()
            self._indexed = index is not None
            if index is None:
                self._scan_linear()
        except SyncauditError:
            self._file.close()
            raise
        except Exception as exc:  # mcap raises many types on damaged bytes
            self._file.close()
            raise LogOpenError(f"{path}: not a readable MCAP file: {one_line(exc)}") from exc

    # -- opening -----------------------------------------------------------------------

    def _check_header(self) -> None:
        """Refuse a file whose first record is not a complete MCAP Header: nothing to read."""
        self._file.seek(len(MAGIC))
        head = self._file.read(RECORD_HEAD.size)
        if len(head) < RECORD_HEAD.size:
            raise LogOpenError(f"{self.path}: MCAP file cut off before its header record")
        opcode, length = RECORD_HEAD.unpack(head)
        if opcode != Opcode.HEADER:
            raise LogOpenError(
                f"{self.path}: not a valid MCAP file: first record is "
                f"{_opcode_name(opcode)}, not a header"
            )
        if len(MAGIC) + RECORD_HEAD.size + length > self._size:
            raise LogOpenError(f"{self.path}: MCAP file cut off inside its header record")

    def _load_index(self) -> Summary | None:
        """The summary section if it can drive indexed reading, else None (read linearly)."""
        self._file.seek(max(self._size - len(MAGIC), 0))
        if self._size < 2 * len(MAGIC) or self._file.read(len(MAGIC)) != MAGIC:
            return None  # no closing magic: cut off; the scan reports where
        try:
            summary = self._reader.get_summary()
        except Exception as exc:
            self.warn(
                "mcap-bad-summary",
                f"{self.path}: MCAP summary section unreadable ({one_line(exc)}); "
                "scanning the file linearly",
            )
            return None
        if summary is None:
            self.warn(
                "mcap-no-summary",
                f"{self.path}: MCAP has no summary section (index); scanning the file linearly",
            )
            return None
        complete = all(
            c.schema_id == 0 or c.schema_id in summary.schemas for c in summary.channels.values()
        )
        if not summary.chunk_indexes or not summary.channels or not complete:
            # Unchunked or empty file, or a summary without the channels the reader needs:
            # the linear scan is then the index.
            return None
        self._check_summary_channels()
        self._check_chunks(summary)
        self._schemas = dict(summary.schemas)
        self._channels = dict(summary.channels)
        stats = summary.statistics
        if stats is not None:
            counts: dict[int, int] | None = dict(stats.channel_message_counts)
            total: int | None = stats.message_count
            start = stats.message_start_time if stats.message_count else None
            end = stats.message_end_time if stats.message_count else None
        else:
            counts = self._indexed_counts(summary)
            total = None if counts is None else sum(counts.values())
            start = min(c.message_start_time for c in summary.chunk_indexes)
            end = max(c.message_end_time for c in summary.chunk_indexes)
        self.summary = LogSummary(str(self.path), "mcap", start, end, total)
        for cid, channel in self._channels.items():
            self._add_topic(channel, None if counts is None else counts.get(cid, 0))
        return summary

    def _check_summary_channels(self) -> None:
        """Refuse a summary declaring one channel id for two topics (the mcap library keeps
        the last, so the other topic would silently vanish)."""
        self._file.seek(self._size - len(MAGIC) - _FOOTER.size)
        opcode, _length, summary_start, offsets_start, _crc = _FOOTER.unpack(
            self._file.read(_FOOTER.size)
        )
        end = offsets_start or self._size - len(MAGIC) - _FOOTER.size
        if opcode != Opcode.FOOTER or not 0 < summary_start <= end:
            return
        self._file.seek(summary_start)
        section = self._file.read(end - summary_start)
        topics: dict[int, str] = {}
        pos = 0
        while pos + RECORD_HEAD.size <= len(section):
            opcode, length = RECORD_HEAD.unpack_from(section, pos)
            body = pos + RECORD_HEAD.size
            if body + length > len(section):
                return  # damaged summary: the mcap reader reports it
            if opcode == Opcode.CHANNEL:
                try:
                    channel = Channel.read(
                        ReadDataStream(io.BytesIO(section[body : body + length]))
                    )
                except Exception:
                    return
                prior = topics.setdefault(channel.id, channel.topic)
                if prior != channel.topic:
                    raise LogReadError(
                        f"{self.path}: malformed MCAP: channel id {channel.id} is declared "
                        f"twice in the summary at byte {summary_start + pos}, for {prior!r} "
                        f"and {channel.topic!r} (one of the two topics cannot be read)"
                    )
            pos = body + length

    def _check_chunks(self, summary: Summary) -> None:
        """Refuse, at open, chunks whose index or header cannot be true: a size no chunk can
        have (or a decompression bomb), a header disagreeing with its index, log times past
        int64. One small read per chunk (in file order, for the first `HEADER_CHECKS`
        chunks: past that, a huge log is not made to seek through every chunk at open and
        the chunk reader checks each header when it reads it), so `info` and `audit` judge
        a log alike."""
        ordered = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
        for number, ci in enumerate(ordered):
            where = chunk_where(str(self.path), ci.chunk_start_offset)
            if max(ci.message_start_time, ci.message_end_time) > MAX_LOG_TIME_NS:
                channels = summary.channels
                names = sorted(
                    {channels[c].topic for c in ci.message_index_offsets if c in channels}
                )
                raise LogReadError(
                    f"{where} ({', '.join(names) or 'no message index'}): its index gives log "
                    f"times up to {ci.message_end_time} ns, past the int64 range (year 2262): "
                    "corrupt time"
                )
            check_declared_size(where, ci.uncompressed_size, ci.compressed_size)
            if number >= HEADER_CHECKS:
                continue
            self._file.seek(ci.chunk_start_offset)
            head = self._file.read(_CHUNK_RECORD_HEAD.size)
            if len(head) < _CHUNK_RECORD_HEAD.size:
                raise LogReadError(f"{where} runs past the end of the file")
            opcode, _length, _start, _end, size = _CHUNK_RECORD_HEAD.unpack(head)
            if opcode != Opcode.CHUNK:
                raise LogReadError(f"{where}: the chunk index points at no chunk record")
            if size != ci.uncompressed_size:
                check_declared_size(where, size, ci.compressed_size)
                raise LogReadError(
                    f"{where} is corrupt: it declares {size} bytes uncompressed, its index "
                    f"{ci.uncompressed_size}"
                )

    def _indexed_counts(self, summary: Summary) -> dict[int, int] | None:
        """Messages per channel from the message indexes after each chunk (no Statistics).

        None where some chunk has no message index to count from.
        """
        counts: dict[int, int] = {}
        for ci in summary.chunk_indexes:
            if not ci.message_index_offsets:
                return None  # no message index: nothing to count from
            for cid, offset in ci.message_index_offsets.items():
                self._file.seek(offset)
                head = self._file.read(_MESSAGE_INDEX_HEAD.size)
                if len(head) < _MESSAGE_INDEX_HEAD.size:
                    return None
                opcode, _length, channel, records_bytes = _MESSAGE_INDEX_HEAD.unpack(head)
                if opcode != Opcode.MESSAGE_INDEX or channel != cid:
                    return None
                counts[cid] = counts.get(cid, 0) + records_bytes // 16
        return counts

    def _add_topic(self, channel: Channel, count: int | None) -> None:
        schema = self._schemas.get(channel.schema_id)
        prior = self.summary.topics.get(channel.topic)
        if prior is not None:
            count = None if count is None or prior.count is None else count + prior.count
        self.summary.topics[channel.topic] = TopicInfo(
            name=channel.topic,
            msgtype=normalise_type_name(schema.name) if schema else "<no schema>",
            encoding=channel.message_encoding,
            count=count,
            has_definition=bool(schema and schema.data),
        )

    def _scan_linear(self) -> None:
        """Read every record once: counts, time range, chunk list, order, where it is cut."""
        counts: dict[int, int] = {}
        start: int | None = None
        end: int | None = None
        previous = -1
        times: dict[int, list[int]] = {}  # chunk offset -> [length, first, last]
        channels: dict[int, set[int]] = {}  # chunk offset -> channel ids
        with self.path.open("rb") as handle:
            for offset, length, _index, message in self._walk(handle):
                cid, t = message.channel_id, message.log_time
                counts[cid] = counts.get(cid, 0) + 1
                start = t if start is None else min(start, t)
                end = t if end is None else max(end, t)
                self._scan.ordered &= t >= previous
                previous = t
                if offset is None:
                    self._scan.loose = True
                    continue
                span = times.setdefault(offset, [length, t, t])
                span[1], span[2] = min(span[1], t), max(span[2], t)
                channels.setdefault(offset, set()).add(cid)
        self._scan.chunks = [
            _ChunkSpan(off, length, lo, hi, frozenset(channels[off]))
            for off, (length, lo, hi) in times.items()
        ]
        total = sum(counts.values())
        self.summary = LogSummary(str(self.path), "mcap", start, end, total)
        for cid, channel in self._channels.items():
            self._add_topic(channel, counts.get(cid, 0))
        if self._cut is not None and total == 0:
            raise LogReadError(
                f"{self.path}: MCAP cut off {self._cut} (recording interrupted?), before "
                "any complete message: nothing can be read"
            )
        if self._cut is not None:
            self.warn(
                "mcap-truncated",
                f"{self.path}: MCAP cut off {self._cut} (recording interrupted?); "
                f"reading the {total} complete messages before the cut",
            )
        if not self._scan.ordered and self._scan.loose:
            self.warn(
                "mcap-unordered",
                f"{self.path}: unindexed MCAP with messages outside chunks and out of "
                "log-time order; they are read in file order",
            )

    # -- record walking (linear mode) ------------------------------------------------------

    def _walk(self, handle: BinaryIO) -> Iterator[tuple[int | None, int, int, Message]]:
        """(chunk offset or None, chunk length, index, message) for every message, in file order.

        Stops at the footer; where the file ends before it, records the place in `_cut`
        after yielding the complete messages of a partly written chunk.
        """
        handle.seek(len(MAGIC))
        while True:
            offset = handle.tell()
            head = handle.read(RECORD_HEAD.size)
            if len(head) < RECORD_HEAD.size:
                self._cut = (
                    f"at byte {offset}" if not head else f"in a record header at byte {offset}"
                )
                return
            opcode, length = RECORD_HEAD.unpack(head)
            if opcode == Opcode.FOOTER:
                if offset + RECORD_HEAD.size + length + len(MAGIC) > self._size:
                    self._cut = f"inside its footer at byte {offset} (after all data)"
                return
            whole = offset + RECORD_HEAD.size + length <= self._size
            if opcode == Opcode.CHUNK:
                for index, rec in enumerate(self._chunk_records(handle, offset, length)):
                    if isinstance(rec, Message):
                        yield offset, length, index, rec
            elif whole and opcode in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE):
                rec = self._parse_record(offset, opcode, handle.read(length))
                if isinstance(rec, Message) and self._known(rec):
                    yield None, 0, 0, rec
            if not whole:
                name = _opcode_name(opcode)
                self._cut = f"inside a {name} record starting at byte {offset}"
                return
            handle.seek(offset + RECORD_HEAD.size + length)

    def _chunk_records(self, handle: BinaryIO, offset: int, length: int) -> list[Any]:
        """Records of the chunk at `offset` (handle just past its record header).

        A chunk that runs past the end of the file gives the complete records decodable
        from its bytes; a damaged whole chunk raises LogReadError.
        """
        available = self._size - offset - RECORD_HEAD.size
        whole = length <= available
        where = chunk_where(str(self.path), offset)
        if length > MAX_CHUNK_RECORD_BYTES:  # read into memory below: bound it first
            raise LogReadError(
                f"{where} is {length} bytes long, over the "
                f"{MAX_CHUNK_RECORD_BYTES // 2**20} MiB limit for one chunk record "
                "(corrupt or hostile chunk)"
            )
        body = handle.read(min(length, available))
        if whole:
            try:
                chunk = Chunk.read(ReadDataStream(io.BytesIO(body)))
            except Exception as exc:
                raise LogReadError(f"{where} is corrupt: {one_line(exc)}") from exc
            data = decompress_bounded(where, chunk.compression, chunk.data, chunk.uncompressed_size)
            if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
                raise LogReadError(f"{where} is corrupt: CRC of its records does not match")
            records = _parse_records(data, where, tolerant=False)
        else:
            records = _salvage_chunk(body, where)
        kept: list[Any] = []
        for rec in records:
            if isinstance(rec, Schema):
                self._schemas[rec.id] = rec
            elif isinstance(rec, Channel):
                self._register_channel(rec, where)
            elif isinstance(rec, Message):
                if not self._known(rec):
                    continue
                self._check_time(rec, where)
            kept.append(rec)
        return kept

    def _register_channel(self, channel: Channel, where: str) -> None:
        """Remember a channel; one id declared for two topics makes the log malformed."""
        prior = self._channels.get(channel.id)
        if prior is not None and prior.topic != channel.topic:
            raise LogReadError(
                f"{where}: malformed MCAP: channel id {channel.id} is declared twice, for "
                f"{prior.topic!r} and {channel.topic!r} (duplicate channel ids mix two "
                "topics' messages)"
            )
        self._channels[channel.id] = channel

    def _check_time(self, rec: Message, where: str) -> None:
        """Refuse a log time past int64 (a valid u64, but no time: year 2262)."""
        if rec.log_time > MAX_LOG_TIME_NS:
            topic = self._channels[rec.channel_id].topic
            raise LogReadError(
                f"{where}: message on {topic} has log time {rec.log_time} ns, past the int64 "
                "range (year 2262): corrupt time"
            )

    def _parse_record(self, offset: int, opcode: int, body: bytes) -> Any:
        """Parse one Schema, Channel or Message record outside chunks, registering the first two."""
        stream = ReadDataStream(io.BytesIO(body))
        try:
            if opcode == Opcode.SCHEMA:
                schema = Schema.read(stream)
                self._schemas[schema.id] = schema
                return schema
            if opcode == Opcode.CHANNEL:
                channel = Channel.read(stream)
                self._register_channel(channel, f"{self.path}: MCAP record at byte {offset}")
                return channel
            message = Message.read(stream, len(body))
            if message.channel_id in self._channels:
                self._check_time(message, f"{self.path}: MCAP message at byte {offset}")
            return message
        except LogReadError:
            raise
        except Exception as exc:
            raise LogReadError(
                f"{self.path}: corrupt MCAP {_opcode_name(opcode)} record at byte {offset}: "
                f"{one_line(exc)}"
            ) from exc

    def _known(self, rec: Message) -> bool:
        """False (with a warning) for a message whose channel was never declared."""
        if rec.channel_id in self._channels:
            return True
        self.warn(
            "mcap-unknown-channel",
            f"{self.path}: messages on undeclared channel id {rec.channel_id} skipped",
        )
        return False

    # -- reading -----------------------------------------------------------------------

    def _messages(
        self, topics: frozenset[str] | None, start_ns: int | None, stop_ns: int | None
    ) -> Iterator[RawMessage]:
        """Raw messages in log-time order (file order only for the `mcap-unordered` case)."""
        if self._indexed:
            source = self._indexed_messages(topics, start_ns, stop_ns)
        elif self._scan.loose:
            source = self._walked_messages(start_ns, stop_ns)
        else:
            source = self._merged_chunks(topics, start_ns, stop_ns)
        for message in source:
            channel = self._channels[message.channel_id]
            if topics is None or channel.topic in topics:
                yield self.raw_message(channel, message.log_time, message.data)

    def _indexed_messages(
        self, topics: frozenset[str] | None, start_ns: int | None, stop_ns: int | None
    ) -> Iterator[Message]:
        """Messages of the indexed chunks merged by (log time, chunk offset, record index).

        Chunks are read by `ChunkReader` (sizes bounded before allocating), each only once
        the merge reaches its first message time, so memory holds just the chunks that
        overlap in time.
        """
        summary = self._reader.get_summary()
        assert summary is not None
        channels = {
            cid: self._channel_info(ch)
            for cid, ch in self._channels.items()
            if topics is None or ch.topic in topics
        }
        wanted = set(channels)
        heap: list[tuple[int, int, int, Message | tuple[int, int]]] = [
            (
                ci.message_start_time,
                ci.chunk_start_offset,
                -1,
                (ci.chunk_start_offset, ci.chunk_length),
            )
            for ci in summary.chunk_indexes
            if _may_hold(ci.message_index_offsets, wanted)
            and (start_ns is None or ci.message_end_time >= start_ns)
            and (stop_ns is None or ci.message_start_time < stop_ns)
        ]
        heapq.heapify(heap)
        reader = self._chunk_reader()
        try:
            while heap:
                _time, offset, _index, item = heapq.heappop(heap)
                if isinstance(item, Message):
                    yield item
                    continue
                records = reader.read(*item)
                where = chunk_where(str(self.path), offset)
                for index, cid, log_time, data in iter_chunk_messages(
                    records, channels, where=where
                ):
                    if _in_range(log_time, start_ns, stop_ns):
                        message = Message(
                            channel_id=cid,
                            log_time=log_time,
                            data=data,  # type: ignore[arg-type]
                            publish_time=log_time,
                            sequence=0,
                        )
                        heapq.heappush(heap, (log_time, offset, index, message))
        finally:
            reader.close()

    def _chunk_reader(self) -> ChunkReader:
        """The reader of this file's chunks for `messages()` (a buffer per chunk)."""
        return ChunkReader(str(self.path), check_crc=True, reuse=False)

    def _channel_info(self, channel: Channel) -> ChannelInfo:
        schema = self._schemas.get(channel.schema_id)
        msgtype = normalise_type_name(schema.name) if schema else "<no schema>"
        return ChannelInfo(channel.topic, msgtype, channel.message_encoding)

    def read_units(self, topics: frozenset[str]) -> list[ReadUnit] | None:
        """The chunks holding any of `topics`: from the index, or from the linear scan of a
        file without one (a cut-off recording: its partly written last chunk is a
        'mcap-cut-chunk' unit, read up to the cut). None where messages lie outside chunks."""
        summary = self.indexed_summary()
        if summary is None:
            return self._scanned_units(topics)
        wanted = {cid for cid, ch in summary.channels.items() if ch.topic in topics}
        source = str(self.path)
        return [
            ReadUnit(
                source,
                "mcap-chunk",
                ci.chunk_start_offset,
                ci.chunk_length,
                ci.message_start_time,
                ci.message_end_time,
                ci.compressed_size,
            )
            for ci in summary.chunk_indexes
            if _may_hold(ci.message_index_offsets, wanted)
        ]

    def _scanned_units(self, topics: frozenset[str]) -> list[ReadUnit] | None:
        """Units of the chunks the linear scan found (None if some messages are loose)."""
        if self._indexed or self._scan.loose:
            return None
        wanted = {cid for cid, ch in self._channels.items() if ch.topic in topics}
        source = str(self.path)
        units = []
        for span in self._scan.chunks:
            if not span.channels & wanted:
                continue
            full = RECORD_HEAD.size + span.length
            whole = span.offset + full <= self._size
            kind = "mcap-chunk" if whole else "mcap-cut-chunk"
            length = full if whole else self._size - span.offset
            units.append(
                ReadUnit(source, kind, span.offset, length, span.start_ns, span.end_ns, length)
            )
        return units

    def unit_channels(self, topics: frozenset[str]) -> dict[int, ChannelInfo]:
        """Channel id -> topic, type, encoding of the channels on `topics`."""
        return {
            cid: self._channel_info(ch) for cid, ch in self._channels.items() if ch.topic in topics
        }

    def _walked_messages(self, start_ns: int | None, stop_ns: int | None) -> Iterator[Message]:
        """Every message in file order (files with messages outside chunks)."""
        with self.path.open("rb") as handle:
            for _offset, _length, _index, rec in self._walk(handle):
                if _in_range(rec.log_time, start_ns, stop_ns):
                    yield rec

    def _merged_chunks(
        self, topics: frozenset[str] | None, start_ns: int | None, stop_ns: int | None
    ) -> Iterator[Message]:
        """Messages of the scanned chunks merged by log time (ties in file order).

        A chunk is decoded only once the merge reaches its first message time, so memory
        holds just the chunks that overlap in time.
        """
        channels = (
            None
            if topics is None
            else {cid for cid, ch in self._channels.items() if ch.topic in topics}
        )
        heap: list[tuple[int, int, int, Message | _ChunkSpan]] = [
            (span.start_ns, span.offset, -1, span)
            for span in self._scan.chunks
            if (channels is None or span.channels & channels)
            and (start_ns is None or span.end_ns >= start_ns)
            and (stop_ns is None or span.start_ns < stop_ns)
        ]
        heapq.heapify(heap)
        with self.path.open("rb") as handle:
            while heap:
                _time, offset, _index, item = heapq.heappop(heap)
                if isinstance(item, Message):
                    yield item
                    continue
                handle.seek(offset + RECORD_HEAD.size)
                for index, rec in enumerate(self._chunk_records(handle, offset, item.length)):
                    if isinstance(rec, Message) and _in_range(rec.log_time, start_ns, stop_ns):
                        heapq.heappush(heap, (rec.log_time, offset, index, rec))

    def _definitions(self, encoding: str) -> Iterator[Definition]:
        """This file's schemas used by channels of `encoding`, in the channels' order."""
        used = dict.fromkeys(
            c.schema_id for c in self._channels.values() if c.message_encoding == encoding
        )
        for sid in used:
            schema = self._schemas.get(sid)
            if schema is not None:
                where = f"{self.path}: schema {schema.name!r}"
                yield Definition(schema.name, schema.encoding, schema.data, where)

    def indexed_summary(self) -> Summary | None:
        """The MCAP summary where the file has chunk indexes (for chunk-parallel reading)."""
        if not self._indexed:
            return None
        summary = self._reader.get_summary()
        return summary if summary is not None and summary.chunk_indexes else None

    def raw_message(
        self, channel: Channel, log_time_ns: int, data: bytes | memoryview
    ) -> RawMessage:
        """A RawMessage for one payload of `channel`, typed by that channel's own schema.

        Also used for payloads read straight from chunks (`mcap_chunks`).
        """
        schema = self._schemas.get(channel.schema_id)
        msgtype = normalise_type_name(schema.name) if schema else "<no schema>"
        return RawMessage(channel.topic, msgtype, log_time_ns, data, channel.message_encoding)

    def _close(self) -> None:
        self._file.close()


def _may_hold(index_offsets: dict[int, int], wanted: set[int]) -> bool:
    """Whether a chunk may hold messages of `wanted` channels (one without message indexes
    may hold any)."""
    return not index_offsets or bool(wanted.intersection(index_offsets))


def _in_range(t: int, start_ns: int | None, stop_ns: int | None) -> bool:
    return (start_ns is None or t >= start_ns) and (stop_ns is None or t < stop_ns)


def _opcode_name(opcode: int) -> str:
    try:
        return Opcode(opcode).name.lower()
    except ValueError:
        return f"unknown (opcode {opcode:#x})"


def _salvage_chunk(body: bytes, where: str) -> list[Any]:
    """Complete records at the start of a chunk whose bytes were cut off.

    zstd and lz4 decode block by block, so a streaming decompressor returns everything
    before the last damaged block (never more than the declared size, itself bounded);
    the records are then parsed up to the first one that does not fit. A cut inside the
    chunk header leaves nothing.
    """
    try:
        chunk = Chunk.read(ReadDataStream(io.BytesIO(body)))
    except Exception:
        return []
    if chunk.compression not in ("zstd", "lz4", ""):
        return []
    limit = min(chunk.uncompressed_size, MAX_CHUNK_BYTES)
    data = decompress_upto(chunk.compression, chunk.data, limit, tolerant=True)
    return _parse_records(data, where, tolerant=True)


def _parse_records(data: bytes, where: str, *, tolerant: bool) -> list[Any]:
    """Schema, Channel and Message records of decompressed chunk data, in order.

    `tolerant`: stop at the first record that does not fit (a cut chunk); otherwise such
    a record is a LogReadError.
    """
    records: list[Any] = []
    pos = 0
    while pos + RECORD_HEAD.size <= len(data):
        opcode, length = RECORD_HEAD.unpack_from(data, pos)
        body_start = pos + RECORD_HEAD.size
        if body_start + length > len(data):
            break
        stream = ReadDataStream(io.BytesIO(data[body_start : body_start + length]))
        try:
            if opcode == Opcode.SCHEMA:
                records.append(Schema.read(stream))
            elif opcode == Opcode.CHANNEL:
                records.append(Channel.read(stream))
            elif opcode == Opcode.MESSAGE:
                records.append(Message.read(stream, length))
        except Exception as exc:
            if tolerant:
                break
            raise LogReadError(
                f"{where} is corrupt: record {len(records)} unreadable: {one_line(exc)}"
            ) from exc
        pos = body_start + length
    if pos != len(data) and not tolerant:
        raise LogReadError(f"{where}: chunk records overrun the chunk (corrupt chunk)")
    return records


class McapCutChunkUnitReader:
    """Per-worker reader of 'mcap-cut-chunk' units: the complete records of a chunk that
    the end of the file cut off (a recording interrupted while writing it)."""

    def __init__(self, source: str, *, check_crc: bool = False) -> None:
        self.source = source
        self._file = open(source, "rb")  # noqa: SIM115 - closed in close()

    def messages(
        self, unit: ReadUnit, channels: dict[int, ChannelInfo]
    ) -> Iterator[tuple[int, int, int, bytes | memoryview]]:
        """(log time, record index, channel id, payload) of the unit's wanted messages."""
        where = chunk_where(self.source, unit.offset)
        if unit.length > MAX_CHUNK_RECORD_BYTES:
            raise LogReadError(f"{where} is {unit.length} bytes long: over the chunk limit")
        self._file.seek(unit.offset + RECORD_HEAD.size)
        body = self._file.read(max(unit.length - RECORD_HEAD.size, 0))
        for index, rec in enumerate(_salvage_chunk(body, where)):
            if isinstance(rec, Message):
                info = channels.get(rec.channel_id)
                if info is not None:
                    if rec.log_time > MAX_LOG_TIME_NS:
                        raise LogReadError(
                            f"{where}: message on {info.topic} has log time {rec.log_time} ns, "
                            "past the int64 range (year 2262): corrupt time"
                        )
                    yield rec.log_time, index, rec.channel_id, rec.data

    def close(self) -> None:
        """Close the file."""
        self._file.close()
