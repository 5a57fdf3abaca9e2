"""An indexed MCAP read straight from a URL: ranged reads of its index and of its chunks.

The parent (`RemoteMcapLog`: the local `McapLog` over a `remote.file.RemoteFile`) fetches
the head, the footer and the summary section (chunk index, channels, schemas,
statistics) ahead: a few requests, however large the log. Its read
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

from mcap.summary import Summary

from syncaudit.errors import LogOpenError, LogReadError
from syncaudit.logs.mcap.chunks import (
    MAX_LOG_TIME_NS,
    OP_CHUNK,
    RECORD_HEAD,
    ChunkReader,
    check_declared_size,
    chunk_where,
    iter_chunk_messages,
)
from syncaudit.logs.mcap.reader import MAGIC, MAX_CHUNK_RECORD_BYTES, McapLog
from syncaudit.logs.model import ChannelInfo, ReadUnit
from syncaudit.remote.file import (
    RemoteFile,
    RemoteSource,
    RemoteUnindexedError,
    RunStream,
    read_run,
    shared_source,
    signed_url,
)
from syncaudit.remote.ranges import FetchStats, RemoteObject, open_object
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
        source: RemoteSource | None,
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
        self._source = source
        self._slots: list[bytearray] = []

    def read(self, offset: int, length: int) -> memoryview:
        """The decompressed records of the chunk record at `offset` (fetched whole, and
        kept by the source up to `PARENT_CACHE_BYTES`: the workers' runs then skip it)."""
        where = chunk_where(self.path, offset)
        if offset < 0 or length < RECORD_HEAD.size or length > MAX_CHUNK_RECORD_BYTES:
            raise LogReadError(f"{where}: chunk record of {length} bytes cannot be read")
        source = self._source
        data = read_run(self._obj, offset, offset + length, source)
        if (
            source is not None
            and offset not in source.segments
            and source.cached_bytes + length <= PARENT_CACHE_BYTES
        ):
            source.segments[offset] = bytes(data)
            source.cached_bytes += length
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
    """An indexed MCAP behind a URL (http(s):// read directly, other stores via fsspec):
    the local reader over a `RemoteFile` that holds the head, footer and summary."""

    def __init__(self, url: str) -> None:
        self.url = url
        path = UrlPath(public_url(url))
        self._remote = RemoteFile.open(url, HEAD_BYTES)
        try:
            self._hold_index(path)
        except BaseException:
            self._remote.close()
            raise
        super().__init__(path, cast(BinaryIO, self._remote))

    def _hold_index(self, path: UrlPath) -> None:
        """Check the head; fetch the tail and the summary section ahead, one request each
        (nothing when a first open of the URL in this process did)."""
        file = self._remote
        head = file.held(0, min(file.size, HEAD_BYTES))
        if file.size == 0:
            raise LogOpenError(f"{path}: file is empty")
        if head is None or bytes(head[: len(MAGIC)]) != MAGIC:
            raise LogOpenError(f"{path}: not an MCAP file (no MCAP magic at its start)")
        size, head_end = file.size, len(head)
        tail_start = max(head_end, size - TAIL_BYTES)
        if tail_start >= size:
            return
        file.hold(tail_start, size)
        tail = file.held(tail_start, size)
        if tail is None or bytes(tail[-len(MAGIC) :]) != MAGIC or len(tail) < _FOOTER_SUMMARY_START:
            return
        (summary_start,) = struct.unpack_from("<Q", tail, len(tail) - _FOOTER_SUMMARY_START)
        if summary_start > 0:
            file.hold(max(summary_start, head_end), tail_start)  # joined to the tail

    def _scan_linear(self) -> None:
        """No scan over ranged reads (it would read every record): refused, to be fetched."""
        reason = "MCAP without a usable chunk index (cut off or no summary)"
        raise RemoteUnindexedError(
            f"{self.path}: {reason}: it cannot be read by ranges",
            f"{reason}: downloaded whole and scanned",
        )

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
        source = self._remote.source
        return RemoteChunkReader(source.obj, source, check_crc=True, reuse=False)

    def read_units(self, topics: frozenset[str]) -> list[ReadUnit] | None:
        """Runs of chunks holding `topics`, one ranged GET each (see `coalesce_units`)."""
        chunks = super().read_units(topics)
        if chunks is None:
            return None
        summary = self.indexed_summary()
        total = len(summary.chunk_indexes) if summary else 0
        self._remote.source.note_chunks(total, len(chunks), sum(u.length for u in chunks))
        return coalesce_units(chunks, str(self.path))

    @property
    def fetch_stats(self) -> FetchStats:
        """What reading this log has fetched so far (its workers too)."""
        return self._remote.source.stats()


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
        # The parent's source, inherited by fork: its counter, and the bytes it holds.
        self._source = shared_source(source)
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
        stream = RunStream(self._object, unit.offset, end, self._source)
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
