"""The per-worker reader of 'mcap-chunk' units: a stored chunk read record by record from
the file (`mcap_stored`), any other chunk read whole and decompressed (`mcap_chunks`)."""

from __future__ import annotations

from collections.abc import Iterator

from syncaudit.logs.mcap.chunks import ChunkReader, chunk_where, iter_chunk_messages
from syncaudit.logs.mcap.stored import StoredChunks
from syncaudit.logs.model import ChannelInfo, ReadUnit


class McapChunkUnitReader:
    """Per-worker reader of 'mcap-chunk' units of one MCAP file.

    A chunk stored uncompressed is read from the file record by record (`StoredChunks`:
    only record headers and wanted payloads, an image cut to its channel's
    `prefix_bytes`), unless CRCs are checked, which needs every byte; other chunks are
    read whole and decompressed (`ChunkReader`).
    """

    def __init__(self, source: str, *, check_crc: bool = False) -> None:
        self.source = source
        self._reader = ChunkReader(source, check_crc=check_crc)
        self._stored = None if check_crc else StoredChunks(self._reader.fileno, self._reader.size)

    def messages(
        self, unit: ReadUnit, channels: dict[int, ChannelInfo]
    ) -> Iterator[tuple[int, int, int, bytes | memoryview]]:
        """(log time, record index, channel id, payload) of the unit's wanted messages.

        Payloads are views into a buffer reused by the next unit: use them before that.
        """
        where = chunk_where(self.source, unit.offset)
        stored = self._stored
        span = None if stored is None else stored.usable_records(unit.offset, unit.length)
        if stored is not None and span is not None:
            messages = stored.messages(*span, channels, where)
        else:
            records = self._reader.read(unit.offset, unit.length)
            messages = iter_chunk_messages(records, channels, where=where)
        for index, cid, log_time, data in messages:
            yield log_time, index, cid, data

    def close(self) -> None:
        """Close the file."""
        self._reader.close()
