"""Hostile and damaged MCAP input (issue 10): every case is one LogReadError naming the
file and the chunk's offset, found before any large allocation and in bounded time."""

from __future__ import annotations

import random
import struct
import time
from pathlib import Path
from typing import Any

import lz4.frame
import pytest
from mcap.writer import CompressionType, IndexType, Writer

from syncaudit.errors import LogReadError
from syncaudit.logs import open_log
from syncaudit.logs.mcap.chunk_reader import McapChunkUnitReader
from syncaudit.logs.mcap.chunks import iter_chunk_messages
from syncaudit.logs.model import ChannelInfo

LINEAR: dict[str, Any] = {
    "use_summary_offsets": False,
    "use_statistics": False,
    "repeat_channels": False,
    "repeat_schemas": False,
    "index_types": IndexType.NONE,
}


def _write(
    path: Path,
    probe: Any,
    compression: CompressionType,
    *,
    topics: tuple[str, ...] = ("/aaaa", "/bbbb"),
    n: int = 120,
    t0: int = 1_000,
    **extra: Any,
) -> None:
    with path.open("wb") as handle:
        writer = Writer(handle, chunk_size=1_500, compression=compression, **extra)
        writer.start(profile="ros2", library="syncaudit-tests")
        schema = writer.register_schema(probe.type, "ros2msg", probe.definition.encode())
        channels = [writer.register_channel(t, "cdr", schema) for t in topics]
        for i in range(n):
            stamp = t0 + 10 * i
            writer.add_message(
                channels[i % len(channels)], log_time=stamp, data=probe.make(i), publish_time=stamp
            )
        writer.finish()  # type: ignore[no-untyped-call]


def _chunks(data: bytes) -> list[int]:
    """Offsets of the top-level chunk records."""
    offsets, pos = [], 8
    while pos + 9 <= len(data):
        opcode, length = struct.unpack_from("<BQ", data, pos)
        if opcode == 0x02:
            break
        if opcode == 0x06:
            offsets.append(pos)
        pos += 9 + length
    return offsets


def _read_all(path: Path) -> None:
    with open_log(path) as log:
        list(log.messages())


def _set_size(path: Path, size: int, which: int = 0) -> int:
    data = bytearray(path.read_bytes())
    offset = _chunks(bytes(data))[which]
    data[offset + 25 : offset + 33] = size.to_bytes(8, "little")
    path.write_bytes(bytes(data))
    return offset


@pytest.mark.parametrize("size", [2**63, 2**64 - 1, 2**40, 3_000_000_000, 300 * 2**20])
@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.LZ4])
@pytest.mark.parametrize("mode", ["indexed", "linear"])
def test_huge_uncompressed_size_refused_before_allocating(
    tmp_path: Path, probe: Any, size: int, compression: CompressionType, mode: str
) -> None:
    path = tmp_path / "huge.mcap"
    _write(path, probe, compression, **(LINEAR if mode == "linear" else {}))
    offset = _set_size(path, size, which=1)
    began = time.process_time()  # CPU time: the work done, not the machine's load
    with pytest.raises(LogReadError, match="limit for one chunk") as info:
        _read_all(path)
    assert time.process_time() - began < 2.0
    text = str(info.value)
    assert f"{path}: MCAP chunk at offset {offset}" in text and "\n" not in text


def test_huge_size_refused_by_the_worker_reader(tmp_path: Path, probe: Any) -> None:
    path = tmp_path / "huge.mcap"
    _write(path, probe, CompressionType.ZSTD)
    with open_log(path) as log:
        units = log.read_units(frozenset(log.topics))
        channels = log.unit_channels(frozenset(log.topics))
    assert units
    unit = min(units, key=lambda u: u.offset)
    _set_size(path, 2**64 - 1)
    reader = McapChunkUnitReader(str(path))
    try:
        with pytest.raises(LogReadError, match=f"offset {unit.offset} declares"):
            list(reader.messages(unit, channels))
    finally:
        reader.close()


@pytest.mark.parametrize("mode", ["indexed", "linear"])
def test_size_disagreeing_with_the_zstd_frame_header(tmp_path: Path, probe: Any, mode: str) -> None:
    path = tmp_path / "lie.mcap"
    _write(path, probe, CompressionType.ZSTD, **(LINEAR if mode == "linear" else {}))
    data = path.read_bytes()
    offset = _chunks(data)[0]
    real = int.from_bytes(data[offset + 25 : offset + 33], "little")
    _set_size(path, real + 5_000_000)
    # indexed: its chunk index disagrees (found at open); linear: the zstd frame header
    with pytest.raises(LogReadError, match=r"zstd frame header says|its index 1") as info:
        _read_all(path)
    assert f"offset {offset}" in str(info.value)


@pytest.mark.parametrize("mode", ["indexed", "linear"])
def test_ratio_bomb_refused(tmp_path: Path, probe: Any, mode: str) -> None:
    """A small lz4 chunk (no content size in its frame) declaring 100 MiB: over 1024:1."""
    path = tmp_path / "ratio.mcap"
    _write(path, probe, CompressionType.LZ4, **(LINEAR if mode == "linear" else {}))
    _set_size(path, 100 * 2**20)
    with pytest.raises(LogReadError, match="decompression bomb"):
        _read_all(path)


@pytest.mark.parametrize("mode", ["indexed", "linear", "worker"])
def test_lz4_bomb_stops_at_the_declared_size(
    tmp_path: Path, probe: Any, mode: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Chunks whose lz4 frames inflate to 96 MiB more than they declare (written by the
    mcap writer with a padded compressor, so every offset and index is right): refused
    after the declared size, quickly, without inflating the bomb."""
    original = lz4.frame.compress

    def padded(data: bytes, **_kw: Any) -> bytes:
        return bytes(original(bytes(data) + bytes(96 * 2**20), store_size=False))

    path = tmp_path / "bomb.mcap"
    monkeypatch.setattr(lz4.frame, "compress", padded)
    _write(path, probe, CompressionType.LZ4, n=4, **(LINEAR if mode == "linear" else {}))
    monkeypatch.undo()
    assert path.stat().st_size < 2_000_000
    began = time.process_time()  # CPU time: the work done, not the machine's load
    with pytest.raises(LogReadError, match=r"lz4 data holds more bytes|holds more than") as info:
        if mode == "worker":
            with open_log(path) as log:
                units = log.read_units(frozenset(log.topics))
                channels = log.unit_channels(frozenset(log.topics))
            assert units
            reader = McapChunkUnitReader(str(path))
            try:
                list(reader.messages(units[0], channels))
            finally:
                reader.close()
        else:
            _read_all(path)
    assert time.process_time() - began < 2.0
    assert str(path) in str(info.value)


@pytest.mark.parametrize("mode", ["indexed", "linear"])
def test_log_time_past_int64_is_a_read_error(tmp_path: Path, probe: Any, mode: str) -> None:
    path = tmp_path / "time.mcap"
    _write(
        path, probe, CompressionType.ZSTD, t0=2**63 - 500, **(LINEAR if mode == "linear" else {})
    )
    with pytest.raises(LogReadError, match="past the int64 range") as info:
        _read_all(path)
    text = str(info.value)
    assert str(path) in text and "MCAP chunk at offset" in text
    assert "/aaaa" in text or "/bbbb" in text


def test_log_time_past_int64_in_the_worker_reader(tmp_path: Path, probe: Any) -> None:
    """A message time past int64 inside a chunk whose index is sound (uncompressed chunk
    patched after the units were listed): the worker's reader names file, chunk, topic."""
    path = tmp_path / "time.mcap"
    _write(path, probe, CompressionType.NONE)
    with open_log(path) as log:
        units = sorted(log.read_units(frozenset(log.topics)) or [], key=lambda u: u.offset)
        channels = log.unit_channels(frozenset(log.topics))
    unit = units[0]
    data = bytearray(path.read_bytes())
    pos = unit.offset + 9 + 28 + 4 + 8  # the first record of the uncompressed chunk
    while data[pos] != 0x05:
        pos += 9 + int.from_bytes(data[pos + 1 : pos + 9], "little")
    data[pos + 9 + 6 : pos + 9 + 14] = (2**63 + 7).to_bytes(8, "little")
    data[unit.offset + 33 : unit.offset + 37] = bytes(4)  # chunk CRC: not recorded
    path.write_bytes(bytes(data))
    reader = McapChunkUnitReader(str(path))
    try:
        with pytest.raises(LogReadError) as info:
            list(reader.messages(unit, channels))
    finally:
        reader.close()
    text = str(info.value)
    assert text.startswith(f"{path}: MCAP chunk at offset {unit.offset}: message")
    assert "on /aaaa has log time 9223372036854775815 ns, past the int64 range" in text


def _duplicate_channel_ids(path: Path) -> None:
    """Make the /bbbb channel records (in chunks and summary) claim /aaaa's id; CRCs off."""
    data = bytearray(path.read_bytes())
    topic = b"/bbbb"
    pos = data.find(topic)
    count = 0
    while pos >= 0:
        # channel record body: id u16, schema id u16, topic length u32, topic
        head = pos - 8
        if int.from_bytes(data[head + 4 : head + 8], "little") == len(topic):
            data[head : head + 2] = (1).to_bytes(2, "little")
            count += 1
        pos = data.find(topic, pos + 1)
    assert count >= 1
    for offset in _chunks(bytes(data)):
        data[offset + 33 : offset + 37] = bytes(4)  # chunk CRC: not recorded
    data[-12:-8] = bytes(4)  # footer CRC: not recorded
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("mode", ["indexed", "linear"])
def test_duplicate_channel_ids_are_malformed(tmp_path: Path, probe: Any, mode: str) -> None:
    path = tmp_path / "dup.mcap"
    _write(path, probe, CompressionType.NONE, **(LINEAR if mode == "linear" else {}))
    _duplicate_channel_ids(path)
    with pytest.raises(LogReadError, match="channel id 1 is declared twice") as info:
        _read_all(path)
    text = str(info.value)
    assert "malformed" in text and "'/aaaa'" in text and "'/bbbb'" in text and str(path) in text


def test_duplicate_channel_in_a_chunk_seen_by_the_worker_reader() -> None:
    topic = b"/bbbb"
    body = struct.pack("<HHI", 1, 1, len(topic)) + topic + struct.pack("<I", 0)
    record = bytes([0x04]) + len(body).to_bytes(8, "little") + body
    channels = {1: ChannelInfo("/aaaa", "std_msgs/msg/String", "cdr")}
    with pytest.raises(LogReadError, match=r"f\.mcap: MCAP chunk at offset 7: malformed"):
        list(iter_chunk_messages(record, channels, where="f.mcap: MCAP chunk at offset 7"))


def test_overrun_names_file_and_offset(tmp_path: Path, probe: Any) -> None:
    path = tmp_path / "overrun.mcap"
    _write(path, probe, CompressionType.NONE)
    with open_log(path) as log:
        units = sorted(log.read_units(frozenset(log.topics)) or [], key=lambda u: u.offset)
        channels = log.unit_channels(frozenset(log.topics))
    unit = units[1]
    data = bytearray(path.read_bytes())
    records_at = unit.offset + 9 + 28 + 4 + 8  # chunk head, empty compression name, length
    data[records_at + 1 : records_at + 9] = (10**6).to_bytes(8, "little")  # first record
    data[unit.offset + 33 : unit.offset + 37] = bytes(4)
    path.write_bytes(bytes(data))
    reader = McapChunkUnitReader(str(path))
    try:
        with pytest.raises(LogReadError) as info:
            list(reader.messages(unit, channels))
    finally:
        reader.close()
    assert str(info.value) == (
        f"{path}: MCAP chunk at offset {unit.offset}: chunk records overrun the chunk "
        "(corrupt chunk)"
    )


@pytest.mark.parametrize("compression", [CompressionType.ZSTD, CompressionType.NONE])
@pytest.mark.parametrize("into", [5, 40, 400])
def test_cut_inside_the_first_chunk_says_so(
    tmp_path: Path, probe: Any, compression: CompressionType, into: int
) -> None:
    path = tmp_path / "cut.mcap"
    with path.open("wb") as handle:
        writer = Writer(handle, chunk_size=1_000_000, compression=compression)
        writer.start(profile="ros2", library="syncaudit-tests")
        schema = writer.register_schema(probe.type, "ros2msg", probe.definition.encode())
        channel = writer.register_channel("/a", "cdr", schema)
        noise = random.Random(1)
        for i in range(40):
            data = noise.randbytes(4000)
            writer.add_message(channel, log_time=1_000 + i, data=data, publish_time=1_000)
        writer.finish()  # type: ignore[no-untyped-call]
    data = path.read_bytes()
    first = _chunks(data)[0]
    path.write_bytes(data[: first + into])
    with pytest.raises(LogReadError, match=r"cut off .* before any complete message") as info:
        open_log(path)
    assert f"byte {first}" in str(info.value)


@pytest.mark.parametrize("size", [2**63, 2**40, 3_000_000_000])
def test_info_and_audit_agree_on_a_hostile_chunk(tmp_path: Path, size: int) -> None:
    """The sample log with one chunk's size made hostile: `info` and `audit` both exit 3
    with one line naming the file and the chunk (info once exited 0 on such files)."""
    from typer.testing import CliRunner

    from syncaudit.cli import app

    repo = Path(__file__).resolve().parents[2]
    sample = repo / "sample_logs" / "vlp16_three_cameras.mcap"
    path = tmp_path / "hostile.mcap"
    path.write_bytes(sample.read_bytes())
    offset = _set_size(path, size, which=-1)
    rig = str(sample) + ".rig.yaml"
    for command in (["info", str(path)], ["audit", str(path), "--rig", rig]):
        result = CliRunner().invoke(app, command)
        assert result.exit_code == 3, (command, result.output)
        assert f"MCAP chunk at offset {offset}" in result.output
        assert "Traceback" not in result.output


def test_linear_chunk_record_length_bounded(tmp_path: Path, probe: Any) -> None:
    """An unindexed MCAP whose first chunk record claims 2^62 bytes: refused, not read."""
    path = tmp_path / "long.mcap"
    _write(path, probe, CompressionType.ZSTD, **LINEAR)
    data = bytearray(path.read_bytes())
    offset = _chunks(bytes(data))[0]
    data[offset + 1 : offset + 9] = (2**62).to_bytes(8, "little")
    path.write_bytes(bytes(data))
    with pytest.raises(LogReadError, match="limit for one chunk record") as info:
        _read_all(path)
    assert f"MCAP chunk at offset {offset}" in str(info.value)
