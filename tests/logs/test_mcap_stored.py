"""Uncompressed MCAP chunks read record by record from the file (`mcap_stored`), checked
against the `mcap` library's reader, with images cut to their prefix and pixels unread."""

from __future__ import annotations

import os
import random
import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from syncaudit.errors import LogReadError
from syncaudit.logs import open_log
from syncaudit.logs.mcap import stored as mcap_stored
from syncaudit.logs.mcap.chunk_reader import McapChunkUnitReader
from syncaudit.logs.mcap.chunks import ChunkReader
from syncaudit.logs.mcap.stored import WINDOW_BYTES
from syncaudit.logs.model import ChannelInfo, ReadUnit

PREFIX = 256
"""The image prefix the audit asks for (collect.IMAGE_PREFIX_BYTES)."""
TOPICS = ("/scan", "/image", "/exposure", "/unwanted")


def _payload_sizes(rng: random.Random) -> Iterator[tuple[int, int]]:
    """(channel index, payload bytes): LiDAR scans larger than many pages, images, small
    records, and sizes around the window and page edges (0 included)."""
    edges = [0, 1, PREFIX - 1, PREFIX, PREFIX + 1, 4095, 4096, 4097, WINDOW_BYTES * 2 + 3]
    for i in range(160):
        kind = i % 8
        if kind == 0:
            yield 0, rng.choice([761_000, 120_001, 9_000])
        elif kind in (1, 5):
            yield 1, rng.choice([350_000, 20_000, *edges])
        elif kind == 7:
            yield 3, rng.choice([300_000, 50])
        else:
            yield 2, rng.choice([rng.randrange(0, 200), *edges])


def _write(path: Path, *, chunk_size: int = 1_100_000, seed: int = 7) -> None:
    """An MCAP with uncompressed chunks (as rosbags writes them) of the four topics."""
    rng = random.Random(seed)
    with path.open("wb") as handle:
        writer = Writer(handle, chunk_size=chunk_size, compression=CompressionType.NONE)
        writer.start(profile="ros2", library="syncaudit-tests")
        schema = writer.register_schema("std_msgs/msg/String", "ros2msg", b"string data\n")
        channels = [writer.register_channel(t, "cdr", schema) for t in TOPICS]
        for i, (which, size) in enumerate(_payload_sizes(rng)):
            stamp = 1_000_000 + 1_000 * i
            writer.add_message(
                channels[which], log_time=stamp, data=rng.randbytes(size), publish_time=stamp
            )
        writer.finish()  # type: ignore[no-untyped-call]


def _units(path: Path) -> tuple[list[ReadUnit], dict[int, ChannelInfo]]:
    """The chunks of the three wanted topics (file order), images marked for their prefix."""
    wanted = frozenset(TOPICS[:3])
    with open_log(path) as log:
        units = sorted(log.read_units(wanted) or [], key=lambda u: u.offset)
        channels = log.unit_channels(wanted)
    marked = {
        cid: ChannelInfo(i.topic, i.msgtype, i.encoding, PREFIX if i.topic == "/image" else 0)
        for cid, i in channels.items()
    }
    return units, marked


def _expected(path: Path) -> list[tuple[str, int, bytes]]:
    """(topic, log time, payload as the audit gets it) of every wanted message, by the
    `mcap` library."""
    with path.open("rb") as handle:
        return [
            (ch.topic, m.log_time, m.data[:PREFIX] if ch.topic == "/image" else m.data)
            for _s, ch, m in make_reader(handle).iter_messages(log_time_order=False)
            if ch.topic in TOPICS[:3]
        ]


def _read(path: Path, **options: Any) -> list[tuple[str, int, bytes]]:
    """Every wanted message through the unit reader, copied when yielded; each unit's
    payloads are checked again once the unit is done (earlier views must stay intact)."""
    units, channels = _units(path)
    got: list[tuple[str, int, bytes]] = []
    reader = McapChunkUnitReader(str(path), **options)
    try:
        for unit in units:
            views = []
            for log_time, _index, cid, data in reader.messages(unit, channels):
                got.append((channels[cid].topic, log_time, bytes(data)))
                views.append(data)
            assert [bytes(v) for v in views] == [g[2] for g in got[len(got) - len(views) :]]
    finally:
        reader.close()
    return got


def test_payloads_equal_the_mcap_library(tmp_path: Path) -> None:
    path = tmp_path / "plain.mcap"
    _write(path)
    expected = _expected(path)
    assert len(expected) == 140 and max(len(d) for _t, _l, d in expected) == 761_000
    assert any(len(d) == PREFIX for t, _l, d in expected if t == "/image")
    assert _read(path) == expected
    # The CRC-checking path (the whole chunk, through ChunkReader) hands over whole images.
    whole = _read(path, check_crc=True)
    assert any(len(d) > PREFIX for t, _l, d in whole if t == "/image")
    assert [(t, lt, d[:PREFIX] if t == "/image" else d) for t, lt, d in whole] == expected


@pytest.mark.parametrize("chunk_size", [1, 5_000, 4_000_000])
def test_any_chunking(tmp_path: Path, chunk_size: int) -> None:
    """A message per chunk, small chunks, and one chunk for everything."""
    path = tmp_path / "plain.mcap"
    _write(path, chunk_size=chunk_size, seed=chunk_size)
    assert _read(path) == _expected(path)


def test_record_indexes_are_the_chunk_walk(tmp_path: Path) -> None:
    """Index in unit counts every record of the chunk, as `iter_chunk_messages` does."""
    from syncaudit.logs.mcap.chunks import iter_chunk_messages

    path = tmp_path / "plain.mcap"
    _write(path)
    units, channels = _units(path)
    stored = McapChunkUnitReader(str(path))
    whole = ChunkReader(str(path), reuse=False)
    try:
        for unit in units:
            mine = [(i, c, t) for t, i, c, _d in stored.messages(unit, channels)]
            records = whole.read(unit.offset, unit.length)
            theirs = [(i, c, t) for i, c, t, _d in iter_chunk_messages(records, channels)]
            assert mine == theirs
    finally:
        stored.close()
        whole.close()


def test_image_pixels_and_unwanted_payloads_are_never_read(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Bytes read from the file: the wanted payloads (images cut to their prefix) and
    record headers, not the pixels or the unwanted topic."""
    path = tmp_path / "plain.mcap"
    _write(path)
    wanted = sum(len(d) for _t, _l, d in _expected(path))
    read: list[int] = []
    real_preadv, real_pread = os.preadv, os.pread

    def preadv(fd: int, buffers: list[memoryview], offset: int) -> int:
        got = real_preadv(fd, buffers, offset)
        read.append(got)
        return got

    def pread(fd: int, n: int, offset: int) -> bytes:
        data = real_pread(fd, n, offset)
        read.append(len(data))
        return data

    monkeypatch.setattr(mcap_stored.os, "preadv", preadv)
    monkeypatch.setattr(mcap_stored.os, "pread", pread)
    assert len(_read(path)) == 140
    units, _channels = _units(path)
    windows = sum(1 for n in read if n <= WINDOW_BYTES)
    # every chunk: one window for its head; then one per record run after a skipped payload
    assert windows >= len(units)
    assert sum(read) <= wanted + WINDOW_BYTES * windows
    # what was skipped (image pixels, /unwanted) dwarfs the windows' slack
    assert WINDOW_BYTES * windows < (os.path.getsize(path) - wanted) / 4, (windows, wanted)


def _damage(path: Path, unit: ReadUnit, at: int, value: bytes) -> None:
    """Overwrite bytes `at` into the chunk record (its CRC set to 'not recorded')."""
    data = bytearray(path.read_bytes())
    data[unit.offset + at : unit.offset + at + len(value)] = value
    data[unit.offset + 33 : unit.offset + 37] = bytes(4)
    path.write_bytes(bytes(data))


def _error(path: Path, unit: ReadUnit, channels: dict[int, ChannelInfo]) -> str:
    reader = McapChunkUnitReader(str(path))
    try:
        with pytest.raises(LogReadError) as info:
            list(reader.messages(unit, channels))
    finally:
        reader.close()
    text = str(info.value)
    assert text.startswith(f"{path}: MCAP chunk at offset {unit.offset}") and "\n" not in text
    return text


RECORDS_AT = 9 + 28 + 4 + 8


@pytest.mark.parametrize(
    ("at", "value", "message"),
    [
        (0, b"\x07", "no chunk record there"),
        (25, struct.pack("<Q", 2**64 - 1), "limit for one chunk"),  # declared size
        (25, struct.pack("<Q", 12), "uncompressed chunk holds"),  # size disagrees
        (37, struct.pack("<I", 2**32 - 1), "compression name runs past it"),
        (41, struct.pack("<Q", 2**63), "data runs past the chunk record"),
        (RECORDS_AT + 1, struct.pack("<Q", 2**62), "chunk records overrun the chunk"),
        (RECORDS_AT + 1, struct.pack("<Q", 4), "chunk records overrun the chunk"),
    ],
)
def test_damaged_chunk_is_one_line_as_before(
    tmp_path: Path, at: int, value: bytes, message: str
) -> None:
    """A damaged head goes to `ChunkReader.read`, which says what it always said; damage
    in the records is found by the walk, in the same words; no hostile length allocates."""
    path = tmp_path / "plain.mcap"
    _write(path)
    units, channels = _units(path)
    unit = units[1]
    _damage(path, unit, at, value)
    assert message in _error(path, unit, channels)


def test_message_with_a_hostile_length_in_a_later_window(tmp_path: Path) -> None:
    """A wanted message record far into the chunk claiming 2^63 bytes: overrun, nothing
    allocated (its payload would be read only once the record is known to fit)."""
    path = tmp_path / "plain.mcap"
    _write(path)
    units, channels = _units(path)
    data = path.read_bytes()
    unit = next(u for u in units if u.length > 1_000_000)
    pos, end, last = unit.offset + RECORDS_AT, unit.offset + unit.length, -1
    while pos < end:  # the last message record of the chunk
        opcode, length = struct.unpack_from("<BQ", data, pos)
        if opcode == 0x05:
            last = pos
        pos += 9 + length
    assert last - unit.offset > WINDOW_BYTES
    _damage(path, unit, last - unit.offset + 1, struct.pack("<Q", 2**63))
    assert "chunk records overrun the chunk" in _error(path, unit, channels)


@pytest.mark.parametrize("when", ["before", "after"])
def test_file_cut(tmp_path: Path, when: str) -> None:
    """The file cut inside the chunk before the reader opens it (the head check sends the
    chunk to `ChunkReader`) or under the open reader (a short read): one line, no crash."""
    path = tmp_path / "plain.mcap"
    _write(path)
    units, channels = _units(path)
    unit = max(units, key=lambda u: u.offset)
    if when == "before":
        os.truncate(path, unit.offset + unit.length // 2)
    reader = McapChunkUnitReader(str(path))
    try:
        os.truncate(path, unit.offset + unit.length // 2)
        with pytest.raises(LogReadError, match="runs past the end of the file") as info:
            list(reader.messages(unit, channels))
    finally:
        reader.close()
    assert f"{path}: MCAP chunk at offset {unit.offset}" in str(info.value)


def test_channel_redefined_inside_a_chunk(tmp_path: Path) -> None:
    """A Channel record in an uncompressed chunk that gives a wanted id another topic."""
    path = tmp_path / "plain.mcap"
    _write(path)
    units, channels = _units(path)
    data = bytearray(path.read_bytes())
    topic = b"/unwanted"
    scan_id = next(cid for cid, i in channels.items() if i.topic == "/scan")
    done = 0
    for unit in units:
        pos, end = unit.offset + RECORDS_AT, unit.offset + unit.length
        while pos < end:
            opcode, length = struct.unpack_from("<BQ", data, pos)
            body = pos + 9
            if opcode == 0x04 and data[body + 8 : body + 8 + len(topic)] == topic:
                data[body : body + 2] = struct.pack("<H", scan_id)
                data[unit.offset + 33 : unit.offset + 37] = bytes(4)
                done += 1
            pos = body + length
    assert done == 1
    path.write_bytes(bytes(data))
    unit = next(u for u in units if bytes(data[u.offset : u.offset + u.length]).find(topic) > 0)
    text = _error(path, unit, channels)
    assert f"channel id {scan_id} is declared twice, for '/scan' and '/unwanted'" in text


def _chunk_record(records: bytes) -> bytes:
    """A chunk record holding `records` uncompressed (CRC 0: not recorded)."""
    body = struct.pack("<QQQI", 0, 0, len(records), 0) + struct.pack("<I", 0)
    body += struct.pack("<Q", len(records)) + records
    return bytes([0x06]) + struct.pack("<Q", len(body)) + body


def _message(channel: int, log_time: int, payload: bytes) -> bytes:
    body = struct.pack("<HIQQ", channel, 0, log_time, log_time) + payload
    return bytes([0x05]) + struct.pack("<Q", len(body)) + body


@pytest.mark.parametrize("first_wanted", [True, False])
@pytest.mark.parametrize("k", range(0, 48))
def test_records_across_the_window_edge(tmp_path: Path, k: int, first_wanted: bool) -> None:
    """The second record's header starts `k` bytes before the end of the chunk's first
    window (its header, message head or payload cut by the window's edge), against the
    in-memory walk of the same records."""
    from syncaudit.logs.mcap.chunks import iter_chunk_messages

    first = (bytes(range(256)) * 16)[: WINDOW_BYTES - k - RECORDS_AT - 31]
    records = (
        _message(1 if first_wanted else 9, 10, first)
        + _message(1, 20, bytes(range(200, 0, -1)) * 3)
        + _message(2, 30, b"x" * k)
        + _message(9, 40, b"unwanted")
    )
    lead = b"\xaa" * 100  # the chunk does not start at the file's beginning
    chunk = _chunk_record(records)
    path = tmp_path / "chunk.bin"
    path.write_bytes(lead + chunk + b"\xbb" * 50)
    channels = {
        1: ChannelInfo("/one", "std_msgs/msg/String", "cdr"),
        2: ChannelInfo("/two", "std_msgs/msg/String", "cdr", prefix_bytes=5),
    }
    expected = [
        (i, c, t, bytes(d)[:5] if c == 2 else bytes(d))
        for i, c, t, d in iter_chunk_messages(records, channels)
    ]
    assert len(expected) == (3 if first_wanted else 2)
    with path.open("rb") as handle:
        stored = mcap_stored.StoredChunks(handle.fileno(), len(lead) + len(chunk) + 50)
        span = stored.usable_records(len(lead), len(chunk))
        assert span == (len(lead) + RECORDS_AT, len(records))
        got = [(i, c, t, bytes(d)) for i, c, t, d in stored.messages(*span, channels, "here")]
    assert got == expected
