"""Read an indexed MCAP chunk by chunk: the unit worker processes split a log by.

A chunk is read with one seek and one read, decompressed (zstd, lz4 or none) and walked
record by record with `struct`, yielding message payloads as memoryviews without
copying; records of unwanted channels are skipped unread. Damage (short read, bad
compression, CRC mismatch, records that do not tile the chunk) is a LogReadError.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass

import lz4.frame
import zstandard

from syncaudit.errors import LogReadError

OP_CHUNK = 0x06
OP_MESSAGE = 0x05
_RECORD_HEAD = struct.Struct("<BQ")
_CHUNK_HEAD = struct.Struct("<QQQI")  # start, end, uncompressed size, uncompressed crc
_MESSAGE_HEAD = struct.Struct("<HIQQ")  # channel, sequence, log time, publish time


@dataclass(frozen=True, slots=True)
class ChunkRef:
    """Where a chunk sits in the file, as the summary's chunk index says."""

    offset: int
    length: int
    start_ns: int
    end_ns: int
    compressed_size: int


def group_chunks(chunks: list[ChunkRef], target_bytes: int) -> list[list[ChunkRef]]:
    """Consecutive chunks (in time order) grouped to about `target_bytes` compressed each."""
    groups: list[list[ChunkRef]] = []
    current: list[ChunkRef] = []
    size = 0
    for chunk in sorted(chunks, key=lambda c: (c.start_ns, c.offset)):
        current.append(chunk)
        size += chunk.compressed_size
        if size >= target_bytes:
            groups.append(current)
            current, size = [], 0
    if current:
        groups.append(current)
    return groups


class ChunkReader:
    """Reads chunks of one MCAP file with a reused buffer: one seek, one read, no copies."""

    def __init__(self, path: str, check_crc: bool = False) -> None:
        self.path = path
        self.check_crc = check_crc
        self._file = open(path, "rb", buffering=0)  # noqa: SIM115 - closed in close()
        self._buffer = bytearray()
        self._zstd = zstandard.ZstdDecompressor()

    def read(self, ref: ChunkRef) -> bytes:
        """The decompressed records of one chunk (checked against its CRC if asked)."""
        where = f"{self.path}: MCAP chunk at offset {ref.offset}"
        if len(self._buffer) < ref.length:
            self._buffer = bytearray(ref.length)
        view = memoryview(self._buffer)[: ref.length]
        self._file.seek(ref.offset)
        if self._file.readinto(view) != ref.length:
            raise LogReadError(f"{where} runs past the end of the file")
        try:
            opcode, _length = _RECORD_HEAD.unpack_from(view, 0)
            if opcode != OP_CHUNK:
                raise LogReadError(f"{where}: no chunk record there")
            pos = 9
            _start, _end, size, crc = _CHUNK_HEAD.unpack_from(view, pos)
            pos += _CHUNK_HEAD.size
            (name_len,) = struct.unpack_from("<I", view, pos)
            compression = bytes(view[pos + 4 : pos + 4 + name_len]).decode()
            pos += 4 + name_len
            (data_len,) = struct.unpack_from("<Q", view, pos)
            pos += 8
            data = view[pos : pos + data_len]
            if compression == "zstd":
                records = self._zstd.decompress(data, max_output_size=size)
            elif compression == "lz4":
                records = bytes(lz4.frame.decompress(data))
            elif compression == "":
                records = bytes(data)
            else:
                raise LogReadError(f"{where}: unsupported compression {compression!r}")
        except (struct.error, zstandard.ZstdError, RuntimeError, ValueError) as exc:
            raise LogReadError(f"{where} is corrupt: {' '.join(str(exc).split())}") from exc
        if len(records) != size or (self.check_crc and crc and zlib.crc32(records) != crc):
            raise LogReadError(f"{where} is corrupt: size or CRC of its records does not match")
        return records

    def close(self) -> None:
        """Close the file."""
        self._file.close()


def iter_chunk_messages(
    records: bytes, channels: frozenset[int]
) -> Iterator[tuple[int, int, int, memoryview]]:
    """(record index, channel id, log time, payload) of each wanted message in a chunk."""
    view = memoryview(records)
    pos, index, end = 0, 0, len(records)
    head = _RECORD_HEAD.size
    while pos + head <= end:
        opcode, length = _RECORD_HEAD.unpack_from(records, pos)
        body = pos + head
        if body + length > end or (opcode == OP_MESSAGE and length < _MESSAGE_HEAD.size):
            break  # reported below: the records do not tile the chunk
        if opcode == OP_MESSAGE:
            channel, _seq, log_time, _pub = _MESSAGE_HEAD.unpack_from(records, body)
            if channel in channels:
                yield index, channel, log_time, view[body + _MESSAGE_HEAD.size : body + length]
        pos = body + length
        index += 1
    if pos != end:
        raise LogReadError("MCAP chunk records overrun the chunk (corrupt chunk)")
