"""An indexed MCAP read straight from a URL: ranged reads of its index and of its chunks.

The parent (`RemoteMcapLog`) fetches the head, the footer and the summary section (chunk
index, channels, schemas, statistics): a few requests, however large the log. Its read
units ('mcap-remote-chunks') are runs of consecutive chunks holding audited topics,
coalesced across the small gaps between them (the message-index records) up to
`RANGE_BYTES`; each worker process streams its runs with one ranged GET each
(`remote.ranges`: one connection per worker, retried from where a dropped reply stopped)
and decodes each chunk as it arrives with the local reader's chunk decoding
(`ChunkReader`), so the socket's buffer fills while the previous chunk is decoded. No copy
of the file is written anywhere.

Against the local reader: chunk headers are checked against the index when a worker
reads them, not at open (that would cost one request per chunk); an MCAP without a
usable index (cut off, no summary) cannot be read by chunks and is refused with
`RemoteUnindexedError`, for the caller to download it whole.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Iterator
from typing import BinaryIO, cast

from mcap.reader import SeekingReader
from mcap.summary import Summary

from syncaudit.errors import LogOpenError, LogReadError, SyncauditError
from syncaudit.logs.mcap.chunks import (
    MAX_LOG_TIME_NS,
    OP_CHUNK,
    RECORD_HEAD,
    ChunkReader,
    check_declared_size,
    chunk_where,
    iter_chunk_messages,
)
from syncaudit.logs.mcap.reader import MAGIC, MAX_CHUNK_RECORD_BYTES, McapLog, _Scan
from syncaudit.logs.model import ChannelInfo, ReadUnit
from syncaudit.logs.typesys import one_line
from syncaudit.remote.file import RemoteFile, RemoteUnindexedError, RunStream
from syncaudit.remote.ranges import (
    RemoteObject,
    Tracker,
    acquire_tracker,
    find_tracker,
    open_object,
    read_head,
    read_range,
    release_tracker,
    signed_url,
)
from syncaudit.remote.urls import UrlPath, public_url

KIND = "mcap-remote-chunks"
HEAD_BYTES = 1 << 10
"""First read: the magic and the head of the header record (all `McapLog` checks)."""
TAIL_BYTES = 16 << 10
"""Second read: the footer, and for most logs the whole summary section."""
RANGE_BYTES = 24 << 20
"""Largest run of chunks one GET reads (and one worker task holds): as `collect`'s
GROUP_BYTES, so tasks are as many as for the local file."""
GAP_BYTES = 64 << 10
"""Chunks of a run may be this far apart: the message indexes between them are read too."""
PARENT_CACHE_BYTES = 64 << 20
"""Chunks the parent's own `messages()` fetched (topic probes, /tf_static) that it keeps,
so that the workers' runs do not fetch them again."""
_FOOTER_SUMMARY_START = 28
"""Bytes from the end of the file to the footer's summary_start field (u64)."""


class RemoteChunkReader(ChunkReader):
    """`ChunkReader`'s decoding over chunk records fetched from a URL.

    `read(offset, length)` fetches and decodes one chunk (the parent's `messages()`);
    `decode(record, where, slot=k)` decodes a record a worker streamed into memory, into
    the k-th of its reused buffers (so payloads of every chunk of a run stay valid until
    the next run is read).
    """

    def __init__(
        self,
        obj: RemoteObject,
        tracker: Tracker | None,
        *,
        check_crc: bool = False,
        reuse: bool = True,
    ) -> None:
        # No file to open: ChunkReader's decoding needs only these.
        self.path = obj.name
        self.check_crc = check_crc
        self.reuse = reuse
        self._out = bytearray()
        self._zstd = None
        self._obj = obj
        self._tracker = tracker
        self._slots: list[bytearray] = []

    def read(self, offset: int, length: int) -> memoryview:
        """The decompressed records of the chunk record at `offset` (fetched whole, and
        kept in the tracker up to `PARENT_CACHE_BYTES`: the workers' runs then skip it)."""
        where = chunk_where(self.path, offset)
        if offset < 0 or length < RECORD_HEAD.size or length > MAX_CHUNK_RECORD_BYTES:
            raise LogReadError(f"{where}: chunk record of {length} bytes cannot be read")
        tracker = self._tracker
        data = bytearray(length)
        stream = RunStream(self._obj, offset, offset + length, tracker)
        try:
            stream.readinto(memoryview(data))
        finally:
            stream.close()
        if (
            tracker is not None
            and offset not in tracker.segments
            and tracker.cached_bytes + length <= PARENT_CACHE_BYTES
        ):
            tracker.segments[offset] = bytes(data)
            tracker.cached_bytes += length
        return self.decode(memoryview(data)[:length], where)

    def decode(self, record: memoryview, where: str, *, slot: int | None = None) -> memoryview:
        """The decompressed records of a whole chunk record, checked as `ChunkReader.read`."""
        if slot is not None:
            while len(self._slots) <= slot:
                self._slots.append(bytearray())
            self._out = self._slots[slot]
        size, crc, records = self._records(record, where)
        if slot is not None:
            self._slots[slot] = self._out
        if len(records) != size or (self.check_crc and crc and zlib.crc32(records) != crc):
            raise LogReadError(f"{where} is corrupt: size or CRC of its records does not match")
        return records

    def close(self) -> None:
        """Nothing to close (the connection belongs to the process)."""


class RemoteMcapLog(McapLog):
    """An indexed MCAP behind a URL (http(s):// read directly, other stores via fsspec)."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.path = UrlPath(public_url(url))
        self.warnings = []
        self._schemas = {}
        self._channels = {}
        self._cut = None
        self._scan = _Scan()
        self._tracker = acquire_tracker(url)
        try:
            self._object = open_object(url)
            self._size = self._fetch_index()
            self._file = cast(BinaryIO, RemoteFile(self._object, self._size, self._tracker))
            self._reader = SeekingReader(self._file, validate_crcs=True)
            self._check_header()
            if self._load_index() is None:
                reason = "MCAP without a usable chunk index (cut off or no summary)"
                self._tracker.ranged = False
                self._tracker.whole_reason = f"{reason}: downloaded whole and scanned"
                raise RemoteUnindexedError(f"{self.path}: {reason}: it cannot be read by ranges")
            self._indexed = True
        except SyncauditError:
            release_tracker(self._tracker)
            raise
        except Exception as exc:  # mcap raises many types on damaged bytes
            release_tracker(self._tracker)
            raise LogOpenError(f"{self.path}: not a readable MCAP file: {one_line(exc)}") from exc

    def _fetch_index(self) -> int:
        """Fetch head, tail and summary section (once per tracked log); the file size."""
        tracker = self._tracker
        if tracker.segments:
            return tracker.size_bytes
        head, size = read_head(self._object, HEAD_BYTES, tracker.counter)
        if size == 0:
            raise LogOpenError(f"{self.path}: file is empty")
        if not head.startswith(MAGIC):
            raise LogOpenError(f"{self.path}: not an MCAP file (no MCAP magic at its start)")
        segments = {0: head}
        tail_start = max(len(head), size - TAIL_BYTES)
        if tail_start < size:
            tail = read_range(self._object, tail_start, size, tracker.counter)
            if tail.endswith(MAGIC) and len(tail) >= _FOOTER_SUMMARY_START:
                (summary_start,) = struct.unpack_from("<Q", tail, len(tail) - _FOOTER_SUMMARY_START)
                start = max(summary_start, len(head))
                if summary_start > 0 and start < tail_start:
                    # One segment from the summary to the end: its records read across.
                    summary = read_range(self._object, start, tail_start, tracker.counter)
                    tail, tail_start = summary + tail, start
            segments[tail_start] = tail
        tracker.segments.update(segments)
        tracker.size_bytes = size
        return size

    def _check_chunks(self, summary: Summary) -> None:
        """Refuse, at open, chunk indexes that cannot be true (a size no chunk can have, a
        decompression bomb, log times past int64); the chunk headers themselves are
        checked by the worker that reads them (here they would cost a request each)."""
        for ci in summary.chunk_indexes:
            where = chunk_where(str(self.path), ci.chunk_start_offset)
            if max(ci.message_start_time, ci.message_end_time) > MAX_LOG_TIME_NS:
                raise LogReadError(
                    f"{where}: its index gives log times up to {ci.message_end_time} ns, past "
                    "the int64 range (year 2262): corrupt time"
                )
            check_declared_size(where, ci.uncompressed_size, ci.compressed_size)
            if ci.chunk_start_offset + ci.chunk_length > self._size:
                raise LogReadError(f"{where} runs past the end of the file")

    def _chunk_reader(self) -> ChunkReader:
        """Chunks for `messages()`: fetched one by one, each into its own buffer."""
        return RemoteChunkReader(self._object, self._tracker, check_crc=True, reuse=False)

    def read_units(self, topics: frozenset[str]) -> list[ReadUnit] | None:
        """Runs of chunks holding `topics`, one ranged GET each (see `coalesce_units`)."""
        chunks = super().read_units(topics)
        if chunks is None:
            return None
        summary = self.indexed_summary()
        self._tracker.chunks_total = len(summary.chunk_indexes) if summary else 0
        self._tracker.chunks_fetched = len(chunks)
        self._tracker.needed_chunk_bytes = sum(unit.length for unit in chunks)
        return coalesce_units(chunks, str(self.path))

    def fetch_stats(self) -> Tracker:
        """What this log's reading has fetched so far (shared with its workers)."""
        return self._tracker

    def _close(self) -> None:
        self._file.close()
        release_tracker(self._tracker)


def coalesce_units(chunks: list[ReadUnit], url: str) -> list[ReadUnit]:
    """Chunk units merged, in file order, into runs no more than `GAP_BYTES` apart and
    `RANGE_BYTES` long (a larger chunk is a run of its own)."""
    runs: list[ReadUnit] = []
    for chunk in sorted(chunks, key=lambda u: u.offset):
        end = chunk.offset + chunk.length
        if runs:
            last = runs[-1]
            if (
                0 <= chunk.offset - (last.offset + last.length) <= GAP_BYTES
                and end - last.offset <= RANGE_BYTES
            ):
                runs[-1] = ReadUnit(
                    url,
                    KIND,
                    last.offset,
                    end - last.offset,
                    min(last.start_ns, chunk.start_ns),
                    max(last.end_ns, chunk.end_ns),
                    end - last.offset,
                )
                continue
        runs.append(
            ReadUnit(
                url, KIND, chunk.offset, chunk.length, chunk.start_ns, chunk.end_ns, chunk.length
            )
        )
    return runs


class RemoteChunksUnitReader:
    """Per-worker reader of 'mcap-remote-chunks' units: one ranged GET per run, streamed
    record by record; each chunk decoded as soon as its bytes are in."""

    def __init__(self, source: str, *, check_crc: bool = False) -> None:
        self.source = source
        self._object = open_object(signed_url(source))
        # The parent's tracker, inherited by fork: its counter, and the bytes it holds.
        self._tracker = find_tracker(source)
        self._counter = self._tracker.counter if self._tracker is not None else None
        self._decoder = RemoteChunkReader(self._object, None, check_crc=check_crc)
        self._input = bytearray()
        self._head = bytearray(RECORD_HEAD.size)

    def messages(
        self, unit: ReadUnit, channels: dict[int, ChannelInfo]
    ) -> Iterator[tuple[int, int, int, bytes | memoryview]]:
        """(log time, index in run, channel id, payload) of the run's wanted messages.

        The index is (chunk's place in the run << 32) | record index, so runs merge in
        the order the local reader's chunks do. Payloads stay valid until the next run.
        """
        end = unit.offset + unit.length
        stream = RunStream(self._object, unit.offset, end, self._tracker)
        try:
            pos, ordinal = unit.offset, 0
            while pos < end:
                where = chunk_where(self._object.name, pos)
                opcode, length = self._record_head(stream, pos, end, where)
                if pos == unit.offset and opcode != OP_CHUNK:
                    raise LogReadError(f"{where}: the chunk index points at no chunk record")
                if opcode != OP_CHUNK:  # a message index between two chunks of the run
                    _skip(stream, length)
                    pos += RECORD_HEAD.size + length
                    continue
                records = self._chunk(stream, length, where, ordinal)
                base = ordinal << 32
                for index, cid, log_time, data in iter_chunk_messages(
                    records, channels, where=where
                ):
                    yield log_time, base | index, cid, data
                pos += RECORD_HEAD.size + length
                ordinal += 1
        finally:
            stream.close()

    def _record_head(self, stream: RunStream, pos: int, end: int, where: str) -> tuple[int, int]:
        """(opcode, length) of the record at `pos`, which must end within the run."""
        if end - pos < RECORD_HEAD.size:
            raise LogReadError(f"{where}: a record is cut by the end of the indexed chunks")
        stream.readinto(memoryview(self._head))
        opcode, length = RECORD_HEAD.unpack(self._head)
        if pos + RECORD_HEAD.size + length > end:
            raise LogReadError(
                f"{where}: record of {length} bytes runs past the indexed chunk "
                "(corrupt chunk index or record)"
            )
        return int(opcode), int(length)

    def _chunk(self, stream: RunStream, length: int, where: str, ordinal: int) -> memoryview:
        """Stream the rest of a chunk record into memory and decode it."""
        total = RECORD_HEAD.size + length
        if total > MAX_CHUNK_RECORD_BYTES:
            raise LogReadError(f"{where} is {total} bytes long: over the chunk limit")
        if len(self._input) < total:
            self._input = bytearray(total)
        view = memoryview(self._input)[:total]
        view[: RECORD_HEAD.size] = self._head
        stream.readinto(view[RECORD_HEAD.size :])
        return self._decoder.decode(view, where, slot=ordinal)

    def close(self) -> None:
        """Nothing to release: the connection belongs to the worker process."""


def _skip(stream: RunStream, length: int) -> None:
    """Read past `length` bytes of the stream."""
    scratch = memoryview(bytearray(min(length, 1 << 16)))
    while length > 0:
        step = min(length, len(scratch))
        stream.readinto(scratch[:step])
        length -= step
