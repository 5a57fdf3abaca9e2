"""The lazy LZ4 frame decoder against the LZ4 library's own frames (python-lz4), and hostile frames."""

from __future__ import annotations

import os
import random
import struct
import tracemalloc
from pathlib import Path

import lz4.frame
import pytest

from lz4_layouts import LZ4_LAYOUTS
from syncaudit.logs.ros1.lz4_frame import (
    FileSpan,
    FrameError,
    FrameSource,
    Pieces,
    decode_frame,
    piece_bytes,
)

FRAMES = {
    **LZ4_LAYOUTS,
    "linked-4mb": {"block_size": lz4.frame.BLOCKSIZE_MAX4MB, "store_size": False},
}


def content(seed: int, size: int = 3_000_000) -> bytes:
    """Camera-like content: incompressible runs (JPEG pixels) between compressible ones
    (headers, metadata, repeated text a block may refer back to)."""
    rng = random.Random(seed)
    parts: list[bytes] = []
    total = 0
    while total < size:
        if rng.random() < 0.5:
            part = rng.randbytes(rng.randrange(1, 300_000))
        else:
            part = b"header frame_id=cam%d " % rng.randrange(6) * rng.randrange(1, 8000)
        parts.append(part)
        total += len(part)
    return b"".join(parts)[:size]


def joined(pieces: Pieces) -> bytes:
    assert pieces.starts == [sum(map(len, pieces.buffers[:i])) for i in range(len(pieces.buffers))]
    return b"".join(bytes(piece_bytes(b, 0, len(b))) for b in pieces.buffers)


@pytest.mark.parametrize("name", sorted(FRAMES))
def test_decodes_what_the_lz4_library_encodes(name: str) -> None:
    # an incompressible run longer than two of the largest blocks: one is stored whole
    data = content(len(name)) + random.Random(1).randbytes(9 << 20) + content(2, 500_000)
    frame = lz4.frame.compress(data, **FRAMES[name])
    pieces = decode_frame(memoryview(frame), len(data))
    assert pieces.size == len(data) and joined(pieces) == data
    stored = [b for b in pieces.buffers if isinstance(b, memoryview)]
    assert stored and len(stored) < len(pieces.buffers)  # both kinds of block were met
    assert all(b.obj is memoryview(frame).obj for b in stored)  # views of the input, no copy


def test_bytes_after_the_frame_are_ignored_as_the_frame_decoder_does() -> None:
    data = content(7, 200_000)
    frame = lz4.frame.compress(data)
    assert joined(decode_frame(memoryview(frame + b"trailing"), len(data))) == data
    assert lz4.frame.decompress(frame + b"trailing") == data


def _refused(frame: bytes | bytearray, size: int) -> str:
    with pytest.raises(FrameError) as info:
        decode_frame(memoryview(frame), size)
    return str(info.value)


def test_damaged_descriptors_are_refused() -> None:
    data = content(3, 100_000)
    frame = lz4.frame.compress(data)
    for at, value, problem in [
        (0, 0x00, "no LZ4 frame magic"),
        (4, frame[4] ^ 0x80, "version"),
        (4, frame[4] | 0x02, "reserved"),
        (5, frame[5] | 0x01, "reserved"),
        (4, frame[4] | 0x01, "dictionary"),
        (5, 0x30, "block maximum size id 3"),
        (14, frame[14] ^ 0x01, "header checksum"),
    ]:
        bad = bytearray(frame)
        bad[at] = value
        assert problem in _refused(bad, len(data))
    assert "says 100000 bytes of content, not 99999" in _refused(frame, len(data) - 1)


def test_a_frame_cut_anywhere_is_refused() -> None:
    data = content(4, 300_000)
    for options in FRAMES.values():
        frame = lz4.frame.compress(data, **options)
        for cut in range(0, len(frame), 997):
            _refused(frame[:cut], len(data))
        _refused(frame[:-1] if options.get("content_checksum") else frame[:-4], len(data))


def test_blocks_that_lie_about_their_size_or_bytes_are_refused() -> None:
    data = content(5, 200_000)
    frame = bytearray(lz4.frame.compress(data, block_size=lz4.frame.BLOCKSIZE_MAX64KB))
    first = 15  # magic, FLG, BD, content size, HC
    (word,) = struct.unpack_from("<I", frame, first)
    over = bytearray(frame)
    struct.pack_into("<I", over, first, (word & 0x80000000) | (64 * 1024 + 1))
    assert "over the frame's 65536-byte maximum" in _refused(over, len(data))
    short = lz4.frame.compress(data, store_size=False)
    assert "frame holds 200000 bytes, not 200001" in _refused(short, len(data) + 1)
    assert "199999 bytes" in _refused(short, len(data) - 1)  # past it, or more than it
    # a compressed block with garbage in it
    packed = lz4.frame.compress(b"abc" * 50_000, store_size=False)
    garbage = bytearray(packed)
    garbage[12:40] = b"\xff" * 28
    assert "damaged or decodes past" in _refused(garbage, 150_000)


def test_a_decompression_bomb_stops_at_the_expected_size() -> None:
    """64 MiB of zeros in 4 MiB blocks (~250 KB of frame) expected as 1 MiB: refused,
    having decoded at most one block."""
    frame = lz4.frame.compress(
        bytes(64 << 20), block_size=lz4.frame.BLOCKSIZE_MAX4MB, store_size=False
    )
    assert len(frame) < 400_000
    tracemalloc.start()
    try:
        problem = _refused(frame, 1 << 20)
        _now, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert "decodes past 1048576 bytes" in problem or "more than 1048576" in problem
    assert peak < 6 << 20


@pytest.mark.parametrize("name", sorted(FRAMES))
def test_a_frame_read_from_its_file_leaves_stored_blocks_there(name: str, tmp_path: Path) -> None:
    """Decoded from a file (after 100 bytes of something else), stored blocks are spans of
    the file, read only when asked; a file that shrinks under them is a FrameError."""
    data = content(len(name)) + random.Random(2).randbytes(9 << 20)
    frame = lz4.frame.compress(data, **FRAMES[name])
    path = tmp_path / "frame.bin"
    path.write_bytes(bytes(100) + frame)
    fd = os.open(path, os.O_RDONLY)
    try:
        source = FrameSource(fd=fd, offset=100, length=len(frame), head=frame[:50])
        pieces = decode_frame(source, len(data))
        assert joined(pieces) == data
        spans = [p for p in pieces.buffers if isinstance(p, FileSpan)]
        assert spans and len(spans) < len(pieces.buffers)
        os.truncate(path, 100 + len(frame) // 2)
        with pytest.raises(FrameError, match="file ends inside a block"):
            joined(pieces)
        with pytest.raises(FrameError, match="file ends inside a block"):
            spans[-1].read_into(memoryview(bytearray(len(spans[-1]))), 0)
    finally:
        os.close(fd)
