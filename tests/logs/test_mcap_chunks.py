"""mcap_chunks (chunk-by-chunk reading for parallel extraction) agrees with McapLog.messages."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from mcap.writer import CompressionType, Writer

from syncaudit.errors import LogReadError
from syncaudit.logs import open_log
from syncaudit.logs.mcap.chunks import ChunkReader, iter_chunk_messages
from syncaudit.logs.mcap.reader import McapLog
from syncaudit.logs.model import ReadUnit
from syncaudit.logs.unit_readers import group_units


def _write(path: Path, probe: Any, compression: CompressionType, n: int = 300) -> None:
    """Three channels, the last two on one topic with different schemas; times interleave."""
    with path.open("wb") as handle:
        writer = Writer(handle, chunk_size=2_000, compression=compression)
        writer.start(profile="ros2", library="syncaudit-tests")
        probe_schema = writer.register_schema(probe.type, "ros2msg", probe.definition.encode())
        string_schema = writer.register_schema("std_msgs/msg/String", "ros2msg", b"string data\n")
        channels = [
            writer.register_channel("/a", "cdr", probe_schema),
            writer.register_channel("/shared", "cdr", probe_schema),
            writer.register_channel("/shared", "cdr", string_schema),
        ]
        for i in range(n):
            stamp = 1_000 + 10 * i - (15 if i % 7 == 3 else 0)  # a few late arrivals
            writer.add_message(
                channels[i % 3], log_time=stamp, data=probe.make(i), publish_time=stamp
            )
        writer.finish()


def _refs(log: McapLog) -> list[ReadUnit]:
    units = log.read_units(frozenset(log.topics))
    assert units is not None
    return sorted(units, key=lambda u: u.offset)


@pytest.mark.parametrize(
    "compression", [CompressionType.NONE, CompressionType.LZ4, CompressionType.ZSTD]
)
def test_chunk_reading_matches_messages(
    tmp_path: Path, probe: Any, compression: CompressionType
) -> None:
    path = tmp_path / "log.mcap"
    _write(path, probe, compression)
    log = open_log(path)
    assert isinstance(log, McapLog)
    with log:
        summary = log.indexed_summary()
        assert summary is not None and len(summary.chunk_indexes) > 5
        keyed = []
        reader = ChunkReader(str(path), check_crc=True)
        for ref in _refs(log):
            records = reader.read(ref.offset, ref.length)
            for index, cid, stamp, data in iter_chunk_messages(
                records, frozenset(summary.channels)
            ):
                raw = log.raw_message(summary.channels[cid], stamp, bytes(data))
                keyed.append(
                    ((stamp, ref.offset, index), (raw.topic, raw.msgtype, stamp, raw.data))
                )
        keyed.sort(key=lambda k: k[0])
        via_chunks = [k[1] for k in keyed]
        via_log = [(m.topic, m.msgtype, m.log_time_ns, bytes(m.data)) for m in log.messages()]
    assert via_chunks == via_log and len(via_log) == 300
    # one topic, two channels, two types: each message keeps its own channel's type
    assert {(t, ty) for t, ty, _, _ in via_log} == {
        ("/a", probe.type),
        ("/shared", probe.type),
        ("/shared", "std_msgs/msg/String"),
    }


def test_channel_filter(tmp_path: Path, probe: Any) -> None:
    path = tmp_path / "log.mcap"
    _write(path, probe, CompressionType.ZSTD)
    reader = ChunkReader(str(path))
    with open_log(path) as log:
        assert isinstance(log, McapLog)
        got = [
            cid
            for ref in _refs(log)
            for _i, cid, _t, _d in iter_chunk_messages(
                reader.read(ref.offset, ref.length), frozenset({2})
            )
        ]
    assert got == [2] * 100


def test_damaged_chunk_is_a_log_read_error(tmp_path: Path, probe: Any) -> None:
    path = tmp_path / "log.mcap"
    _write(path, probe, CompressionType.NONE)
    with open_log(path) as log:
        assert isinstance(log, McapLog)
        ref = _refs(log)[1]
    data = bytearray(path.read_bytes())
    at = ref.offset + ref.length - 30  # inside the last message payload of the chunk
    data[at : at + 4] = bytes(b ^ 0xFF for b in data[at : at + 4])
    path.write_bytes(bytes(data))
    with pytest.raises(LogReadError, match="CRC") as info:
        ChunkReader(str(path), check_crc=True).read(ref.offset, ref.length)
    assert str(path) in str(info.value) and "\n" not in str(info.value)
    # Without the CRC check an uncompressed chunk's payload damage goes unseen (by design).
    assert ChunkReader(str(path), check_crc=False).read(ref.offset, ref.length)

    beyond = ReadUnit(str(path), "mcap-chunk", len(data) - 10, 100, 0, 0, 100)
    with pytest.raises(LogReadError, match="past the end"):
        ChunkReader(str(path)).read(beyond.offset, beyond.length)


def test_records_that_do_not_tile_the_chunk_raise() -> None:
    record = bytes([0x05]) + (40).to_bytes(8, "little") + bytes(10)  # claims 40, has 10
    with pytest.raises(LogReadError, match="overrun"):
        list(iter_chunk_messages(record, frozenset({0})))
    short = bytes([0x05]) + (4).to_bytes(8, "little") + bytes(4)  # shorter than a header
    with pytest.raises(LogReadError, match="overrun"):
        list(iter_chunk_messages(short, frozenset({0})))


def test_group_chunks_by_time_and_size() -> None:
    refs = [
        ReadUnit("f", "mcap-chunk", offset=o, length=10, start_ns=s, end_ns=s + 5, cost=40)
        for o, s in [(300, 30), (100, 10), (200, 20), (400, 40), (500, 50)]
    ]
    groups = group_units(refs, target_bytes=100)
    assert [[r.start_ns for r in g] for g in groups] == [[10, 20, 30], [40, 50]]


@pytest.mark.parametrize("damage", ["flip", "short"])
def test_damaged_zstd_chunk_is_a_log_read_error(tmp_path: Path, probe: Any, damage: str) -> None:
    """Damaged compressed data fails to decompress (no CRC check needed) with one line, and
    the reader stays usable for the next chunk."""
    path = tmp_path / "log.mcap"
    _write(path, probe, CompressionType.ZSTD)
    with open_log(path) as log:
        assert isinstance(log, McapLog)
        refs = _refs(log)
    data = bytearray(path.read_bytes())
    ref = refs[1]
    if damage == "flip":
        at = ref.offset + ref.length - 40
        data[at : at + 8] = bytes(b ^ 0xA5 for b in data[at : at + 8])
    else:  # the chunk claims more uncompressed bytes than its frame holds
        size_at = ref.offset + 9 + 16
        size = int.from_bytes(data[size_at : size_at + 8], "little")
        data[size_at : size_at + 8] = (size + 100).to_bytes(8, "little")
    path.write_bytes(bytes(data))
    reader = ChunkReader(str(path))
    try:
        with pytest.raises(LogReadError, match="corrupt") as info:
            reader.read(ref.offset, ref.length)
        assert str(path) in str(info.value) and "\n" not in str(info.value)
        assert len(reader.read(refs[2].offset, refs[2].length)) > 0
    finally:
        reader.close()


def test_uncompressed_chunk_is_read_in_place(tmp_path: Path, probe: Any) -> None:
    """An uncompressed chunk's records are a view of a mapping (no copy, untouched payload
    pages never read), and a view held across later reads stays valid."""
    import mmap

    path = tmp_path / "log.mcap"
    _write(path, probe, CompressionType.NONE)
    with open_log(path) as log:
        refs = _refs(log)
    reader = ChunkReader(str(path))
    try:
        first = reader.read(refs[0].offset, refs[0].length)
        assert isinstance(first.obj, mmap.mmap)
        before = bytes(first)
        for ref in refs[1:]:
            reader.read(ref.offset, ref.length)
        assert bytes(first) == before
        copied = ChunkReader(str(path), reuse=False).read(refs[0].offset, refs[0].length)
        assert not isinstance(copied.obj, mmap.mmap) and bytes(copied) == before
    finally:
        reader.close()
