"""Read an indexed MCAP chunk by chunk: the unit worker processes split a log by.

A chunk is mapped, decompressed (zstd, lz4 or none) into a reused buffer and walked
record by record with `struct`, yielding message payloads as memoryviews without
copying; records of unwanted channels are skipped unread. Damage (short read, bad
compression, CRC mismatch, records that do not tile the chunk) is a LogReadError naming
the file and the chunk's offset.

A chunk's declared uncompressed size is never trusted for an allocation: it must agree
with the compression frame's own header where that records the size, stay below
`MAX_CHUNK_BYTES`, and (for large chunks) below `MAX_RATIO` times the compressed size;
decompression itself is bounded by the declared size, so a decompression bomb is refused
after at most that many bytes.
"""

from __future__ import annotations

import contextlib
import mmap
import os
import struct
import zlib
from collections.abc import Iterator
from typing import TYPE_CHECKING

from syncaudit.errors import LogReadError
from syncaudit.logs.model import ChannelInfo

if TYPE_CHECKING:
    import zstandard

OP_CHANNEL = 0x04
OP_MESSAGE = 0x05
OP_CHUNK = 0x06
RECORD_HEAD = struct.Struct("<BQ")
CHUNK_HEAD = struct.Struct("<QQQI")  # start, end, uncompressed size, uncompressed crc
MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel, sequence, log time, publish time
CHANNEL_HEAD = struct.Struct("<HHI")  # id, schema id, topic length

MAX_LOG_TIME_NS = 2**63 - 1
"""Log times are u64 in MCAP; past int64 they cannot be a time (year 2262) and break numpy."""
MAX_CHUNK_BYTES = 128 * 1024 * 1024
"""Largest uncompressed chunk accepted: writers chunk at 1-64 MiB (rosbag2 768 KiB, mcap
1 MiB, ours 4 MiB) and put a larger message in a chunk of its own; 128 MiB holds any
camera frame or point cloud, and two workers' buffers stay within a few hundred MB."""
MAX_RATIO = 1024
"""Largest uncompressed/compressed ratio accepted for chunks above `RATIO_FLOOR_BYTES`."""
RATIO_FLOOR_BYTES = 16 * 1024 * 1024
"""Chunks up to this size are accepted at any ratio (a small chunk cannot exhaust memory)."""
MAX_READ_BYTES = MAX_CHUNK_BYTES + MAX_CHUNK_BYTES // 64 + 1024 * 1024
"""Longest chunk record read into a buffer: the largest chunk accepted, plus what zstd or
lz4 may add to incompressible data (under 1 %) and the record's header fields."""


def chunk_where(path: str, offset: int) -> str:
    """How messages name a chunk: file and byte offset of its record."""
    return f"{path}: MCAP chunk at offset {offset}"


def check_chunk_size(where: str, compression: str, declared: int, data: bytes | memoryview) -> None:
    """Refuse a chunk whose declared uncompressed size cannot be true, before allocating.

    The zstd frame header (and an lz4 frame header that records it) states the content
    size; it must equal the chunk's. Any size is capped absolutely and, for large chunks,
    by a ratio to the compressed bytes (lz4 cannot exceed ~255:1; zstd of real sensor data
    is far below 1024:1).
    """
    compressed = len(data)
    check_declared_size(where, declared, compressed)
    if compression == "":
        if declared != compressed:
            raise LogReadError(
                f"{where} is corrupt: uncompressed chunk holds {compressed} bytes "
                f"but declares {declared}"
            )
        return
    framed = _frame_content_size(compression, data)
    if framed is not None and framed != declared:
        raise LogReadError(
            f"{where} is corrupt: chunk declares {declared} bytes uncompressed but its "
            f"{compression} frame header says {framed}"
        )


def check_declared_size(where: str, declared: int, compressed: int) -> None:
    """Refuse an uncompressed size over `MAX_CHUNK_BYTES`, or a large one over `MAX_RATIO`
    times the compressed size (a decompression bomb)."""
    if declared > MAX_CHUNK_BYTES:
        raise LogReadError(
            f"{where} declares {declared} bytes uncompressed, over the "
            f"{MAX_CHUNK_BYTES // 2**20} MiB limit for one chunk (corrupt or hostile chunk)"
        )
    if declared > RATIO_FLOOR_BYTES and declared > MAX_RATIO * compressed:
        raise LogReadError(
            f"{where} declares {declared} bytes from {compressed} compressed "
            f"(over {MAX_RATIO}:1): refused as a decompression bomb"
        )


def _frame_content_size(compression: str, data: bytes | memoryview) -> int | None:
    """Content size a zstd/lz4 frame header records, None where it records none."""
    try:
        if compression == "zstd":
            import zstandard

            size = zstandard.frame_content_size(data)
            return None if size < 0 else int(size)
        if compression == "lz4":
            import lz4.frame

            size = int(lz4.frame.get_frame_info(data)["content_size"])
            return size or None  # 0: not recorded
    except Exception:  # a damaged header: the decompressor reports it
        return None
    return None


def decompress_bounded(where: str, compression: str, data: bytes | memoryview, size: int) -> bytes:
    """Decompress chunk data that must yield exactly `size` bytes, never producing more.

    For the readers that do not decompress into a reused buffer (the linear scan).
    """
    check_chunk_size(where, compression, size, data)
    if compression not in ("zstd", "lz4", ""):
        raise LogReadError(f"{where}: unsupported compression {compression!r}")
    try:
        out = decompress_upto(compression, data, size + 1, tolerant=False)
    except Exception as exc:
        raise LogReadError(f"{where} is corrupt: {' '.join(str(exc).split())}") from exc
    if len(out) != size:
        held = "more than" if len(out) > size else str(len(out))
        raise LogReadError(f"{where} is corrupt: its data holds {held} bytes, not {size}")
    return out


def decompress_upto(
    compression: str, data: bytes | memoryview, limit: int, *, tolerant: bool
) -> bytes:
    """At most `limit` bytes of decompressed chunk data.

    `tolerant` (for a chunk cut off by the end of the file): what decodes before the
    damage, instead of an error.
    """
    if compression == "":
        return bytes(data[:limit])
    parts: list[bytes] = []
    got = 0
    try:
        if compression == "zstd":
            import zstandard

            reader = zstandard.ZstdDecompressor().stream_reader(bytes(data))
            with reader:
                while got < limit:
                    part = reader.read(min(limit - got, 1 << 20))
                    if not part:
                        break
                    parts.append(part)
                    got += len(part)
        elif compression == "lz4":
            import lz4.frame

            parts.append(lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=limit))
        else:
            raise ValueError(f"unsupported compression {compression!r}")
    except Exception:
        if not tolerant:
            raise
    return b"".join(parts)


class ChunkReader:
    """Reads chunks of one MCAP file: read into one buffer, decompressed into another.

    Each chunk record is read (`preadv`) into a reused input buffer and decompressed from
    there into a reused output buffer, so resident memory stays one chunk however large
    the log, and nothing is allocated, mapped or unmapped per chunk: on the 2 GB bench log
    this costs a sixth less CPU than mapping each chunk (whose unmapping and page faults
    cost more than the copy out of the page cache). A record longer than any chunk can
    legitimately be (`MAX_READ_BYTES`) is mapped instead, never allocated, so a hostile
    length costs no memory before the size checks refuse it.
    A chunk stored uncompressed (rosbags' and some recorders' MCAP) is mapped and its
    records are returned as a view of the mapping: nothing is copied, and the pages of
    payloads nobody reads (image pixels) are never touched. The mapping goes when the
    last view of it does.
    With `reuse=False` every chunk gets its own output buffer (for callers holding several).
    """

    def __init__(self, path: str, check_crc: bool = False, *, reuse: bool = True) -> None:
        self.path = path
        self.check_crc = check_crc
        self.reuse = reuse
        self._file = open(path, "rb")  # noqa: SIM115 - closed in close()
        self._size = os.fstat(self._file.fileno()).st_size
        self._out = bytearray()
        self._in = bytearray()
        self._zstd: zstandard.ZstdDecompressor | None = None

    def read(self, offset: int, length: int) -> memoryview:
        """The decompressed records of the chunk record at `offset`, valid until the next
        `read` (when reusing its buffer)."""
        where = chunk_where(self.path, offset)
        if offset < 0 or length < RECORD_HEAD.size or offset + length > self._size:
            raise LogReadError(f"{where} runs past the end of the file")
        if self.reuse and self._stored_uncompressed(offset, length):
            size, crc, records = self._read_in_place(offset, length, where)
        elif length > MAX_READ_BYTES:
            size, crc, records = self._read_mapped(offset, length, where)
        else:
            if len(self._in) < length:
                self._in = bytearray(length)
            with memoryview(self._in)[:length] as view:
                if os.preadv(self._file.fileno(), [view], offset) != length:
                    raise LogReadError(f"{where} runs past the end of the file")
                size, crc, records = self._records(view, where)
        if len(records) != size or (self.check_crc and crc and zlib.crc32(records) != crc):
            raise LogReadError(f"{where} is corrupt: size or CRC of its records does not match")
        return records

    @property
    def fileno(self) -> int:
        """The open file's descriptor."""
        return self._file.fileno()

    @property
    def size(self) -> int:
        """The file's size in bytes (when opened)."""
        return self._size

    def _stored_uncompressed(self, offset: int, length: int) -> bool:
        """Whether the chunk record at `offset` names no compression (from its first bytes;
        a damaged head says no, and the buffered read then reports the damage)."""
        name_at = RECORD_HEAD.size + CHUNK_HEAD.size
        head = os.pread(self._file.fileno(), min(length, name_at + 4), offset)
        if len(head) < name_at + 4 or head[0] != OP_CHUNK:
            return False
        (name_len,) = struct.unpack_from("<I", head, name_at)
        return bool(name_len == 0)

    def _read_in_place(self, offset: int, length: int, where: str) -> tuple[int, int, memoryview]:
        """`_records` of an uncompressed chunk as a view of a mapping of it (no copy)."""
        start = offset - offset % mmap.ALLOCATIONGRANULARITY
        mapped = mmap.mmap(
            self._file.fileno(), offset + length - start, offset=start, access=mmap.ACCESS_READ
        )
        whole = memoryview(mapped)
        view = whole[offset - start :]
        try:
            return self._records(view, where, in_place=True)
        except BaseException:
            view.release()
            whole.release()
            with contextlib.suppress(BufferError):
                mapped.close()
            raise
        finally:
            # The records view (if any) keeps the mapping; it is unmapped when that goes.
            view.release()
            whole.release()

    def _read_mapped(self, offset: int, length: int, where: str) -> tuple[int, int, memoryview]:
        """`_records` of a chunk record read through a mapping of it (no allocation)."""
        start = offset - offset % mmap.ALLOCATIONGRANULARITY
        mapped = mmap.mmap(
            self._file.fileno(), offset + length - start, offset=start, access=mmap.ACCESS_READ
        )
        try:
            with memoryview(mapped) as whole:
                view = whole[offset - start :]
                try:
                    return self._records(view, where)
                finally:
                    view.release()
        finally:
            mapped.close()

    def _records(
        self, view: memoryview, where: str, *, in_place: bool = False
    ) -> tuple[int, int, memoryview]:
        """(uncompressed size, CRC, records) of the chunk record in `view`; `in_place`: an
        uncompressed chunk's records are a view of `view`'s memory, not a copy."""
        import zstandard

        try:
            opcode, _length = RECORD_HEAD.unpack_from(view, 0)
            if opcode != OP_CHUNK:
                raise LogReadError(f"{where}: no chunk record there")
            pos = 9
            _start, _end, size, crc = CHUNK_HEAD.unpack_from(view, pos)
            pos += CHUNK_HEAD.size
            (name_len,) = struct.unpack_from("<I", view, pos)
            if pos + 4 + name_len > len(view):
                raise LogReadError(f"{where} is corrupt: its compression name runs past it")
            compression = bytes(view[pos + 4 : pos + 4 + name_len]).decode("utf-8", "replace")
            pos += 4 + name_len
            (data_len,) = struct.unpack_from("<Q", view, pos)
            pos += 8
            if pos + data_len > len(view):
                raise LogReadError(f"{where} is corrupt: its data runs past the chunk record")
            data = view[pos : pos + data_len]
            keep = False
            try:
                if compression not in ("zstd", "lz4", ""):
                    raise LogReadError(f"{where}: unsupported compression {compression!r}")
                check_chunk_size(where, compression, size, data)
                if compression == "zstd":
                    return size, crc, self._unzstd(data, size)
                if compression == "lz4":
                    return size, crc, self._unlz4(data, size)
                if in_place:
                    keep = True
                    return size, crc, data
                return size, crc, self._copy(data)
            finally:
                if not keep:
                    data.release()
        except (struct.error, zstandard.ZstdError, RuntimeError, ValueError) as exc:
            raise LogReadError(f"{where} is corrupt: {' '.join(str(exc).split())}") from exc

    def _buffer(self, size: int) -> memoryview:
        """The first `size` bytes of the reused output buffer (grown when too small)."""
        if not self.reuse:
            return memoryview(bytearray(size))
        if len(self._out) < size:
            self._out = bytearray(size)  # earlier records (views) keep the old one alive
        return memoryview(self._out)[:size]

    def _unzstd(self, data: memoryview, size: int) -> memoryview:
        """Decompress a zstd frame of `size` bytes into the output buffer."""
        import zstandard

        if self._zstd is None:
            self._zstd = zstandard.ZstdDecompressor()
        out = self._buffer(size)
        reader = self._zstd.stream_reader(data, read_across_frames=False, closefd=False)
        try:
            got = reader.readinto(out)
            extra = reader.read(1) if got == size else b""
        finally:
            reader.close()  # type: ignore[no-untyped-call]
            del reader  # releases its hold on `data`, so the mapping can close
        if got != size or extra:
            raise ValueError(f"zstd data holds {'more' if extra else got} bytes, not {size}")
        return out

    def _unlz4(self, data: memoryview, size: int) -> memoryview:
        """Decompress an lz4 frame, stopping one byte past `size` (a bomb stops there)."""
        import lz4.frame

        got = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=size + 1)
        if len(got) != size:
            raise ValueError(
                f"lz4 data holds {'more' if len(got) > size else len(got)} bytes, not {size}"
            )
        return memoryview(got)

    def _copy(self, data: memoryview) -> memoryview:
        """Copy uncompressed records out of the mapping into the output buffer."""
        out = self._buffer(len(data))
        out[:] = data
        return out

    def close(self) -> None:
        """Close the file."""
        self._file.close()


def iter_chunk_messages(
    records: bytes | memoryview,
    channels: dict[int, ChannelInfo] | frozenset[int],
    *,
    where: str = "MCAP chunk",
) -> Iterator[tuple[int, int, int, memoryview]]:
    """(record index, channel id, log time, payload) of each wanted message in a chunk.

    `where` names the chunk in errors (file and offset). Where `channels` maps ids to
    their topics, a Channel record in the chunk that gives a wanted id another topic is
    refused (a malformed log would otherwise mix two topics' messages).
    """
    view = memoryview(records)
    infos = channels if isinstance(channels, dict) else None
    pos, index, end = 0, 0, len(records)
    head = RECORD_HEAD.size
    while pos + head <= end:
        opcode, length = RECORD_HEAD.unpack_from(records, pos)
        body = pos + head
        if body + length > end or (opcode == OP_MESSAGE and length < MESSAGE_HEAD.size):
            break  # reported below: the records do not tile the chunk
        if opcode == OP_MESSAGE:
            channel, _seq, log_time, _pub = MESSAGE_HEAD.unpack_from(records, body)
            if channel in channels:
                if log_time > MAX_LOG_TIME_NS:
                    topic = infos[channel].topic if infos is not None else f"channel {channel}"
                    raise log_time_error(where, index, topic, log_time)
                yield index, channel, log_time, view[body + MESSAGE_HEAD.size : body + length]
        elif opcode == OP_CHANNEL and infos is not None and length >= CHANNEL_HEAD.size:
            check_channel(records, body, length, infos, where)
        pos = body + length
        index += 1
    if pos != end:
        raise overrun_error(where)


def log_time_error(where: str, index: int, topic: str, log_time: int) -> LogReadError:
    """The error for a message whose log time is past int64 (a corrupt time)."""
    return LogReadError(
        f"{where}: message {index} on {topic} has log time {log_time} ns, "
        "past the int64 range (year 2262): corrupt time"
    )


def overrun_error(where: str) -> LogReadError:
    """The error for chunk records that do not tile their chunk."""
    return LogReadError(f"{where}: chunk records overrun the chunk (corrupt chunk)")


def check_channel(
    records: bytes | memoryview, body: int, length: int, infos: dict[int, ChannelInfo], where: str
) -> None:
    """Refuse a Channel record that redefines a wanted channel id with another topic."""
    cid, _schema, topic_len = CHANNEL_HEAD.unpack_from(records, body)
    info = infos.get(cid)
    if info is None or CHANNEL_HEAD.size + topic_len > length:
        return
    start = body + CHANNEL_HEAD.size
    topic = bytes(records[start : start + topic_len]).decode("utf-8", "replace")
    if topic != info.topic:
        raise LogReadError(
            f"{where}: malformed MCAP: channel id {cid} is declared twice, for {info.topic!r} "
            f"and {topic!r} (duplicate channel ids mix two topics' messages)"
        )
