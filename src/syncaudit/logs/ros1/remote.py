"""A ROS 1 bag read straight from a URL: its index section, then ranged reads of its chunks.

The parent (`RemoteRosbag1Log`) fetches the bag header and the index section at the end
of the file (connections and chunk infos: two requests). A bag's index gives where each
chunk starts, not its length; the local reader reads every chunk's record header at open
for it, which remotely would cost one request per chunk. Here a chunk's span runs from
its position to the next chunk's (to the index section for the last): the chunk record
and the index-data records that follow it. Spans tile the data section, so adjacent
spans holding audited topics are merged into runs of up to `RANGE_BYTES`: one
'rosbag1-remote-chunk' unit each, fetched by a worker with one ranged GET into a reused
buffer and walked record by record, each chunk decoded by the local chunk reader
(`Rosbag1ChunkReader`); the record headers are checked there, when the chunks are read.

A bag whose index is missing or damaged (a recording that was not closed) is refused with
`RemoteUnindexedError`: the local reader would scan every record, so the caller
downloads it whole instead.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from typing import BinaryIO, cast

from syncaudit.errors import LogOpenError, LogReadError, SyncauditError
from syncaudit.logs.model import ChannelInfo, ReadUnit
from syncaudit.logs.ros1.format import (
    OP_CHUNK,
    OP_CHUNK_INFO,
    UNIT_KIND,
    BagFile,
    BagFormatError,
    BagIndex,
    Rosbag1ChunkReader,
    read_bag_header,
)
from syncaudit.logs.ros1.reader import Rosbag1Log
from syncaudit.logs.typesys import one_line
from syncaudit.remote.file import (
    RemoteFile,
    RemoteSource,
    RemoteUnindexedError,
    RunStream,
    shared_source,
    signed_url,
)
from syncaudit.remote.ranges import FetchStats, open_object
from syncaudit.remote.urls import UrlPath, public_url

KIND = "rosbag1-remote-chunk"
RANGE_BYTES = 24 << 20
"""Largest run of chunk spans one GET reads (as MCAP runs)."""
HEAD_BYTES = (4 << 10) + 256
"""First read: the magic and the bag header record (rosbag pads it to 4 KiB)."""


class _SpannedBagFile(BagFile):
    """A bag over ranged reads that gives each chunk the span up to the next chunk.

    It notes the chunk positions of the chunk-info records as the index is parsed; asked
    then for the record at a chunk position (the index reader wants each chunk's length),
    it answers with that span, read from nothing.
    """

    def __init__(self, handle: BinaryIO, size: int, index_pos: int) -> None:
        super().__init__(handle, size)
        self._index_pos = index_pos
        self._chunk_positions: set[int] = set()
        self._span_ends: dict[int, int] | None = None

    def record_at(self, offset: int) -> tuple[dict[str, bytes], int, int]:
        """The record's (fields, data offset, data length); a chunk's span for a chunk."""
        if offset < self._index_pos and offset in self._chunk_positions:
            end = self._span_end(offset)
            return {"op": bytes([OP_CHUNK])}, offset, end - offset
        fields, data_at, dlen = super().record_at(offset)
        if fields.get("op") == bytes([OP_CHUNK_INFO]) and len(fields.get("chunk_pos", b"")) == 8:
            self._chunk_positions.add(int.from_bytes(fields["chunk_pos"], "little"))
            self._span_ends = None
        return fields, data_at, dlen

    def _span_end(self, offset: int) -> int:
        if self._span_ends is None:
            starts = sorted(self._chunk_positions)
            self._span_ends = dict(zip(starts, [*starts[1:], self._index_pos], strict=True))
        return self._span_ends[offset]


class RemoteRosbag1Log(Rosbag1Log):
    """A ROS 1 bag (format 2.0) behind a URL, read by chunk spans: the local reader over
    a `RemoteFile` that holds the bag header and the index section."""

    def __init__(self, url: str) -> None:
        self.url = url
        path = UrlPath(public_url(url))
        self._remote = RemoteFile.open(url, HEAD_BYTES)
        try:
            if self._remote.size == 0:
                raise LogOpenError(f"{path}: file is empty")
            super().__init__(path, self._spanned_bag())
        except SyncauditError:
            self._remote.close()
            raise
        except Exception as exc:
            self._remote.close()
            raise LogOpenError(f"{path}: not a readable ROS 1 bag: {one_line(exc)}") from exc
        self._chunk_reader = RemoteRosbag1ChunkReader(url)

    def _spanned_bag(self) -> BagFile:
        """The bag over the remote file, its index section fetched ahead in one request
        (where the header points at one; else the plain bag, for `_load` to refuse)."""
        file = self._remote
        handle = cast(BinaryIO, file)
        try:
            index_pos, _conns, _chunks, first = read_bag_header(BagFile(handle, file.size))
        except (BagFormatError, ValueError):
            return BagFile(handle, file.size)  # not a bag, or a damaged header: `_load` says
        if first <= index_pos < file.size:
            file.hold(index_pos, file.size)
        return _SpannedBagFile(handle, file.size, index_pos)

    def _scan(self, bag: BagFile, first: int, reason: str) -> BagIndex:
        """No scan over ranged reads (it would read every record): refused, to be fetched."""
        raise RemoteUnindexedError(
            f"{self.path}: ROS 1 bag cannot be read by ranges because {reason}",
            f"ROS 1 bag {reason}: downloaded whole and scanned",
        )

    def _units(self, conn_ids: set[int]) -> list[ReadUnit]:
        """Runs of adjacent chunk spans holding `conn_ids` (up to `RANGE_BYTES`), each read
        from the URL with one GET."""
        spans = super()._units(conn_ids)
        needed = sum(unit.length for unit in spans)
        self._remote.source.note_chunks(len(self._index.chunks), len(spans), needed)
        runs: list[ReadUnit] = []
        for span in spans:  # in file order
            last = runs[-1] if runs else None
            end = span.offset + span.length
            if (
                last is not None
                and last.offset + last.length == span.offset
                and end - last.offset <= RANGE_BYTES
            ):
                runs[-1] = dataclasses.replace(
                    last,
                    length=end - last.offset,
                    start_ns=min(last.start_ns, span.start_ns),
                    end_ns=max(last.end_ns, span.end_ns),
                    cost=end - last.offset,
                )
                continue
            runs.append(
                dataclasses.replace(span, source=str(self.path), kind=KIND, cost=span.length)
            )
        return runs

    @property
    def fetch_stats(self) -> FetchStats:
        """What reading this log has fetched so far (its workers too)."""
        return self._remote.source.stats()

    def _close(self) -> None:
        super()._close()
        self._remote.close()


class _RunFile:
    """A run of chunk spans held in memory, read at its file offsets (for `BagFile`)."""

    def __init__(self, data: memoryview, offset: int) -> None:
        self._data, self._offset, self._pos = data, offset, offset

    def seek(self, offset: int, whence: int = 0) -> int:
        self._pos = offset
        return offset

    def read(self, size: int) -> bytes:
        at = self._pos - self._offset
        self._pos += size
        return bytes(self._data[at : at + size])

    def view(self, offset: int, length: int) -> memoryview:
        """Up to `length` held bytes at file offset `offset` (no copy)."""
        at = max(0, offset - self._offset)
        return self._data[at : at + max(0, length)]

    def close(self) -> None:
        """Nothing to close (the buffer belongs to the reader)."""


class RemoteRosbag1ChunkReader(Rosbag1ChunkReader):
    """Per-worker reader of 'rosbag1-remote-chunk' units: a run of chunk spans fetched with
    one ranged GET into a reused buffer, then each chunk decoded by the local reader."""

    def __init__(self, source: str | None = None) -> None:
        super().__init__()
        self._source = source
        self._buffer = bytearray()
        self._shared: RemoteSource | None = None
        if source is None:
            return
        self._object = open_object(signed_url(source))
        self._shared = shared_source(source)  # the parent's, inherited by fork

    def _read(self, bag: BagFile, offset: int, length: int) -> memoryview:
        """The chunk's bytes straight from the run held in memory (the local reader reads
        them from the file descriptor)."""
        return cast(_RunFile, bag.handle).view(offset, length)

    def messages(
        self, unit: ReadUnit, channels: dict[int, ChannelInfo]
    ) -> Iterator[tuple[int, int, int, bytes | memoryview]]:
        """(log time, index in run, connection id, payload) of the run's wanted messages;
        the index is (chunk's place in the run << 32) | message index."""
        if unit.kind != KIND or unit.source != self._source:
            yield from super().messages(unit, channels)
            return
        if len(self._buffer) < unit.length:
            self._buffer = bytearray(unit.length)
        view = memoryview(self._buffer)[: unit.length]
        stream = RunStream(self._object, unit.offset, unit.offset + unit.length, self._shared)
        try:
            stream.readinto(view)
        finally:
            stream.close()
        end = unit.offset + unit.length
        bag = BagFile(cast(BinaryIO, _RunFile(view, unit.offset)), end)
        name = self._object.name  # errors name the URL (no query string)
        self._files[name] = bag
        pos, ordinal = unit.offset, 0
        while pos < end:
            try:
                fields, data_at, dlen = bag.record_at(pos)
            except BagFormatError as exc:
                raise LogReadError(
                    f"{self._object.name}: ROS 1 record at byte {pos}: {exc}"
                ) from None
            if fields.get("op") == bytes([OP_CHUNK]):
                chunk = ReadUnit(name, UNIT_KIND, pos, data_at + dlen - pos, 0, 0, 0)
                base = ordinal << 32
                for log_time, index, conn_id, data in super().messages(chunk, channels):
                    yield log_time, base | index, conn_id, data
                ordinal += 1
            pos = data_at + dlen
