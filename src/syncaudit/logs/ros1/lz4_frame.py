"""An LZ4 frame decoded lazily: a block stored uncompressed stays a view of the input.

Frame format (lz4 `doc/lz4_Frame_format.md`, v1.6): magic 0x184D2204 (little-endian),
a descriptor (FLG: version 01, block independence, block checksum, content size, content
checksum, reserved 0, dictionary id; BD: block maximum size id 4-7 = 64 KiB-4 MiB;
the optional u64 content size and u32 dictionary id; HC, the second byte of the XXH32 of
the descriptor), then blocks: a u32 size whose high bit marks a block stored
uncompressed, its bytes, an optional u32 block checksum; a zero size ends the frame,
followed by an optional u32 content checksum.

An LZ4 compressor stores a block uncompressed when compressing it does not pay, which is
what camera JPEGs make of most of a ROS 1 lz4 chunk (98 % of the blocks of the bench
bag). Writers differ: roslz4 (rosbag's C++ and Python writers) writes independent blocks
of 1 MiB, a content checksum and no content size; rosbags (`lz4.frame.compress`) linked
blocks of 64 KiB, a content size and no checksum; the LZ4 library may add block checksums. Copying those blocks only to skip the image pixels in them costs as much as the
read itself, so `decode_frame` returns the content as `Pieces`: stored blocks are views
of the input, compressed ones are decompressed with `lz4.block` (a linked block with the
previous 64 KiB of content as its dictionary, as the frame decoder does).

What is checked: the magic, the descriptor's reserved bits and version, its header
checksum (XXH32 of at most 14 bytes, by the xxhash library), every block size against the
frame's maximum, that every block decodes, that the blocks hold exactly the size the
caller expects (a frame's own content size must agree) and never more: decompression
is bounded by what is left of that size, so a decompression bomb stops there. What is
not: block and content checksums, which need XXH32 over all the content; callers that
want them verified (`--check-crc`) decode with `lz4.frame` instead, which does.
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass

import lz4.block
import xxhash

MAGIC = 0x184D2204
WINDOW_BYTES = 64 * 1024
"""How far back a linked block may refer: the dictionary is the content's last 64 KiB."""
BLOCK_MAX_BYTES = {4: 64 * 1024, 5: 256 * 1024, 6: 1024 * 1024, 7: 4 * 1024 * 1024}
"""Block maximum size by the BD byte's id."""
_STORED = 0x80000000
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")


class FrameError(ValueError):
    """The bytes are not a well-formed LZ4 frame of the expected size."""


@dataclass(frozen=True, slots=True)
class FrameDescriptor:
    """What a frame's descriptor says."""

    linked: bool
    """Blocks may refer to the previous 64 KiB of content (block independence flag 0)."""
    block_checksum: bool
    content_checksum: bool
    content_size: int | None
    block_max_bytes: int
    blocks_at: int
    """Offset of the first block's size."""


class FileSpan:
    """Bytes of a file not read yet: a stored block of a frame read from the file."""

    __slots__ = ("fd", "length", "offset")

    def __init__(self, fd: int, offset: int, length: int) -> None:
        self.fd, self.offset, self.length = fd, offset, length

    def __len__(self) -> int:
        return self.length

    def read(self, start: int, stop: int) -> bytes:
        """Its bytes `start` to `stop` (a short read is damage: the file shrank)."""
        data = os.pread(self.fd, stop - start, self.offset + start)
        if len(data) != stop - start:
            raise FrameError(f"file ends inside a block (byte {self.offset + start} on)")
        return data

    def read_into(self, out: memoryview, start: int) -> None:
        """Fill `out` with its bytes from `start` on (a short read is damage)."""
        if os.preadv(self.fd, [out], self.offset + start) != len(out):
            raise FrameError(f"file ends inside a block (byte {self.offset + start} on)")


Piece = bytes | memoryview | FileSpan


@dataclass(frozen=True, slots=True)
class Pieces:
    """Content as consecutive pieces: `buffers[i]` holds bytes `starts[i]` on."""

    starts: list[int]
    buffers: list[Piece]
    size: int


def piece_bytes(piece: Piece, start: int, stop: int) -> bytes | memoryview:
    """Bytes `start` to `stop` of a piece (read from the file for a `FileSpan`)."""
    if isinstance(piece, FileSpan):
        return piece.read(start, stop)
    return piece[start:stop]


class FrameSource:
    """The bytes of a frame, by offset in the frame: held in memory, or read from a file
    (`fd`, `offset`: where the frame starts in it), where stored blocks become `FileSpan`s
    and are never read here. `head` holds the frame's first bytes if already read."""

    def __init__(
        self,
        data: bytes | memoryview | None = None,
        *,
        fd: int = -1,
        offset: int = 0,
        length: int = 0,
        head: bytes = b"",
    ) -> None:
        self.data = memoryview(data) if data is not None else None
        self.fd, self.offset = fd, offset
        self.size = len(self.data) if self.data is not None else length
        self._head = head

    def read(self, start: int, length: int) -> bytes | memoryview:
        """Bytes `start` to `start + length` (fewer at the end of the frame)."""
        if self.data is not None:
            return self.data[start : start + length]
        want = max(0, min(length, self.size - start))
        if start + want <= len(self._head):
            return self._head[start : start + want]
        data = os.pread(self.fd, want, self.offset + start)
        if len(data) != want:
            raise FrameError(f"file ends inside the frame (byte {self.offset + start} on)")
        return data

    def stored(self, start: int, length: int) -> Piece:
        """A stored block's bytes: a view of the memory, or a `FileSpan` of the file."""
        if self.data is not None:
            return self.data[start : start + length]
        return FileSpan(self.fd, self.offset + start, length)


def read_descriptor(data: bytes | memoryview) -> FrameDescriptor:
    """The descriptor of the frame starting at `data[0]` (raises FrameError)."""
    if len(data) < 7:
        raise FrameError("frame header cut off")
    (magic,) = _U32.unpack_from(data, 0)
    if magic != MAGIC:
        raise FrameError(f"no LZ4 frame magic (found {magic:#010x})")
    flg, bd = data[4], data[5]
    if flg >> 6 != 1:
        raise FrameError(f"frame version {flg >> 6} is not 1")
    if flg & 0x02 or bd & 0x8F:
        raise FrameError("reserved descriptor bits set")
    if flg & 0x01:
        raise FrameError("frame needs a dictionary (dictionary id set)")
    block_max = BLOCK_MAX_BYTES.get(bd >> 4 & 0x07)
    if block_max is None:
        raise FrameError(f"block maximum size id {bd >> 4 & 0x07} is not 4-7")
    end = 6 + (8 if flg & 0x08 else 0)
    if len(data) < end + 1:
        raise FrameError("frame header cut off")
    content_size = int(_U64.unpack_from(data, 6)[0]) if flg & 0x08 else None
    if (xxhash.xxh32_intdigest(bytes(data[4:end])) >> 8) & 0xFF != data[end]:
        raise FrameError("frame header checksum does not match")
    return FrameDescriptor(
        linked=not flg & 0x20,
        block_checksum=bool(flg & 0x10),
        content_checksum=bool(flg & 0x04),
        content_size=content_size,
        block_max_bytes=block_max,
        blocks_at=end + 1,
    )


def decode_frame(data: memoryview | FrameSource, size: int) -> Pieces:
    """The content of the LZ4 frame at the start of `data`, which must be `size` bytes.

    Stored blocks are views of `data` (a `FileSpan` where the frame is read from a file);
    bytes after the frame's end are ignored (as the LZ4 frame decoder does). Raises
    FrameError on any damage.
    """
    source = data if isinstance(data, FrameSource) else FrameSource(data)
    read, stored = source.read, source.stored
    head = read(0, 23)  # the longest descriptor and the first block's size
    info = read_descriptor(head)
    if info.content_size is not None and info.content_size != size:
        raise FrameError(f"frame header says {info.content_size} bytes of content, not {size}")
    tail = 4 if info.block_checksum else 0
    total = source.size
    pos = info.blocks_at
    starts: list[int] = []
    buffers: list[Piece] = []
    produced = 0
    # A block's size is read with what precedes it where that was read anyway (the
    # descriptor, a compressed block): from a file, a stored block costs one 4-byte read.
    ahead_at, ahead = pos, head[pos : pos + 4]
    while True:
        if pos + 4 > total:
            raise FrameError(f"frame cut off at byte {pos} (no end mark)")
        (word,) = _U32.unpack_from(ahead if ahead_at == pos else read(pos, 4), 0)
        pos += 4
        if word == 0:
            break
        length = word & 0x7FFFFFFF
        if length > info.block_max_bytes:
            raise FrameError(
                f"block at byte {pos - 4} of {length} bytes is over the frame's "
                f"{info.block_max_bytes}-byte maximum"
            )
        if pos + length + tail > total:
            raise FrameError(f"block at byte {pos - 4} cut off")
        left = size - produced
        out: Piece
        if word & _STORED:
            out = stored(pos, length)
        elif left <= 0:
            raise FrameError(f"frame holds more than {size} bytes")
        else:
            raw = read(pos, length + tail + 4)
            ahead_at, ahead = pos + length + tail, raw[length + tail :]
            window = _window(buffers) if info.linked and buffers else b""
            try:
                out = lz4.block.decompress(
                    raw[:length], uncompressed_size=min(info.block_max_bytes, left), dict=window
                )
            except lz4.block.LZ4BlockError:
                raise FrameError(
                    f"block at byte {pos - 4} is damaged or decodes past {size} bytes"
                ) from None
        if len(out) > left:
            raise FrameError(f"frame holds more than {size} bytes")
        if len(out):
            starts.append(produced)
            buffers.append(out)
            produced += len(out)
        pos += length + tail
    if info.content_checksum and pos + 4 > total:
        raise FrameError("content checksum cut off")
    if produced != size:
        raise FrameError(f"frame holds {produced} bytes, not {size}")
    return Pieces(starts, buffers, size)


def _window(buffers: list[Piece]) -> bytes | memoryview:
    """The last `WINDOW_BYTES` of the content decoded so far (a linked block's dictionary)."""
    last = buffers[-1]
    if len(last) >= WINDOW_BYTES:
        return piece_bytes(last, len(last) - WINDOW_BYTES, len(last))
    parts: list[bytes | memoryview] = []
    need = WINDOW_BYTES
    for buffer in reversed(buffers):
        parts.append(piece_bytes(buffer, max(0, len(buffer) - need), len(buffer)))
        need -= len(parts[-1])
        if need <= 0:
            break
    return b"".join(reversed(parts))
