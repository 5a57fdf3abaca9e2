"""Read the wanted messages of an MCAP chunk stored uncompressed from the file, unmapped.

A chunk stored uncompressed (rosbags' MCAP, any writer with compression "") needs no
decompression, so its records are walked where they lie in the file: record headers are
read through a small window (`pread` of `WINDOW_BYTES`: a record header with an image's
header prefix, or a run of small records, in one call), and each wanted payload is copied
once into one reused buffer, from the window where it lies there, else with one `preadv`
straight from the page cache. Payloads nobody reads (an image's pixels past the prefix its
channel asks for, unwanted channels) are neither read nor mapped.

Why not a mapping of the chunk (what this replaced): a LiDAR scan's payload is then
faulted in a few pages at a time on first touch, and every chunk costs an mmap and a
munmap. Reading and decoding every unit of the 2 GB rosbags MCAP bench log (755 VLS-128
scans of 761 KB, 4524 images of 350 KB) with --jobs 1 cost 0.30 CPU s mapped, 0.27 with
the scans prefaulted (MADV_POPULATE_READ), 0.23 with the headers walked in the mapping
and the scans read with `preadv`, 0.19 this way (3 runs each, load average ~2).

The chunk's head is checked by `usable_records` only for being plainly sound: any doubt
sends the chunk to `ChunkReader.read`, which reports the damage as it always has. The
walk itself checks what `iter_chunk_messages` checks, with the same errors.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Iterator

from syncaudit.errors import LogReadError
from syncaudit.logs.mcap.chunks import (
    CHANNEL_HEAD,
    CHUNK_HEAD,
    MAX_CHUNK_BYTES,
    MAX_LOG_TIME_NS,
    MESSAGE_HEAD,
    OP_CHANNEL,
    OP_CHUNK,
    OP_MESSAGE,
    RECORD_HEAD,
    check_channel,
    log_time_error,
    overrun_error,
)
from syncaudit.logs.model import ChannelInfo
from syncaudit.logs.typesys import one_line

WINDOW_BYTES = 4096
"""Bytes read at once where record headers lie: a header and an image's 256-byte prefix,
or the small exposure/trigger records that follow an image, in one `pread` (4-16 KiB
measured alike)."""
_NAME_AT = RECORD_HEAD.size + CHUNK_HEAD.size
_RECORDS_AT = _NAME_AT + 4 + 8  # an empty compression name, then the records' length


class StoredChunks:
    """Reads wanted messages of the uncompressed chunks of one open MCAP file.

    Payloads are views of one buffer, valid until the next chunk is read.
    """

    def __init__(self, fd: int, size: int) -> None:
        self._fd = fd
        self._size = size
        self._window = bytearray(WINDOW_BYTES)
        self._base = self._top = 0
        """File offsets of the window's first byte and the byte past its last."""
        self._out = bytearray()

    def usable_records(self, offset: int, length: int) -> tuple[int, int] | None:
        """(file offset, length) of the records of the chunk record at `offset` where it is
        stored uncompressed and its head is sound; None: read it the general way.

        Reads the chunk's first `WINDOW_BYTES` (its head and first records) into the window.
        """
        if offset < 0 or length < _RECORDS_AT or offset + length > self._size:
            return None
        n = min(length, WINDOW_BYTES)
        try:
            got = os.preadv(self._fd, [memoryview(self._window)[:n]], offset)
        except OSError:
            return None
        self._base, self._top = offset, offset + got
        if got != n or self._window[0] != OP_CHUNK:
            return None
        _start, _end, size, _crc = CHUNK_HEAD.unpack_from(self._window, RECORD_HEAD.size)
        name_len, data_len = struct.unpack_from("<IQ", self._window, _NAME_AT)
        if name_len != 0 or data_len != size or size > MAX_CHUNK_BYTES:
            return None
        if _RECORDS_AT + size > length:
            return None
        return offset + _RECORDS_AT, size

    def messages(
        self, start: int, size: int, channels: dict[int, ChannelInfo], where: str
    ) -> Iterator[tuple[int, int, int, memoryview]]:
        """(record index, channel id, log time, payload) of each wanted message of the
        records at file offset `start`, `size` bytes long (from `usable_records`).

        A channel with `prefix_bytes` gets at most that much of each payload. Damage: a
        LogReadError naming `where`, as `iter_chunk_messages` words it.
        """
        try:
            yield from self._walk(start, start + size, channels, where)
        except OSError as exc:  # the file failed under the reader
            raise LogReadError(f"{where}: cannot read: {one_line(exc)}") from None

    def _walk(
        self, pos: int, end: int, channels: dict[int, ChannelInfo], where: str
    ) -> Iterator[tuple[int, int, int, memoryview]]:
        head, message_head = RECORD_HEAD.size, MESSAGE_HEAD.size
        window = self._window
        out, at = memoryview(self._out), 0
        index = 0
        while pos + head <= end:
            if pos + head + message_head > self._top and self._top < end:
                self._fill(pos, min(WINDOW_BYTES, end - pos), where)
            base = self._base
            opcode, length = RECORD_HEAD.unpack_from(window, pos - base)
            body = pos + head
            if body + length > end or (opcode == OP_MESSAGE and length < message_head):
                break  # reported below: the records do not tile the chunk
            if opcode == OP_MESSAGE:
                channel, _seq, log_time, _pub = MESSAGE_HEAD.unpack_from(window, body - base)
                info = channels.get(channel)
                if info is not None:
                    if log_time > MAX_LOG_TIME_NS:
                        raise log_time_error(where, index, info.topic, log_time)
                    want = length - message_head
                    if 0 < info.prefix_bytes < want:
                        want = info.prefix_bytes
                    if at + want > len(out):
                        # Views of the old buffer stay valid; the new one holds the rest.
                        self._out = bytearray(max(want, min(2 * len(out), end - pos)))
                        out, at = memoryview(self._out), 0
                    payload = out[at : at + want]
                    self._payload(payload, body + message_head, where)
                    at += want
                    yield index, channel, log_time, payload
            elif opcode == OP_CHANNEL and length >= CHANNEL_HEAD.size:
                self._channel(body, length, channels, where)
            pos = body + length
            index += 1
        if pos != end:
            raise overrun_error(where)

    def _fill(self, pos: int, n: int, where: str) -> None:
        """Read `n` bytes from file offset `pos` into the window."""
        if os.preadv(self._fd, [memoryview(self._window)[:n]], pos) != n:
            raise LogReadError(f"{where} runs past the end of the file")
        self._base, self._top = pos, pos + n

    def _payload(self, out: memoryview, pos: int, where: str) -> None:
        """Fill `out` with the file's bytes from offset `pos` (from the window if there)."""
        if self._base <= pos and pos + len(out) <= self._top:
            rel = pos - self._base
            out[:] = memoryview(self._window)[rel : rel + len(out)]
        elif os.preadv(self._fd, [out], pos) != len(out):
            raise LogReadError(f"{where} runs past the end of the file")

    def _channel(
        self, body: int, length: int, channels: dict[int, ChannelInfo], where: str
    ) -> None:
        """Check a Channel record in the chunk (`check_channel`) from the window, or from
        just its id and topic read from the file (never more than the record holds)."""
        rel = body - self._base
        if body + CHANNEL_HEAD.size > self._top:
            self._fill(body, CHANNEL_HEAD.size, where)
            rel = 0
        cid, _schema, topic_len = CHANNEL_HEAD.unpack_from(self._window, rel)
        if cid not in channels or CHANNEL_HEAD.size + topic_len > length:
            return
        need = CHANNEL_HEAD.size + topic_len
        if body + need <= self._top:
            check_channel(memoryview(self._window), body - self._base, length, channels, where)
            return
        part = os.pread(self._fd, need, body)
        if len(part) != need:
            raise LogReadError(f"{where} runs past the end of the file")
        check_channel(part, 0, length, channels, where)
