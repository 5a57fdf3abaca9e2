"""ROS 1 bags through our own reader, checked message by message against rosbags' reader.

Fixtures: the real Ouster bag (shared data) and bags written here with rosbags' Writer in
each chunk compression ROS 1 knows (none, bz2, lz4 frames), small chunks, several
connections, one topic recorded by two nodes, and log times out of order inside chunks (a
recorder writes in arrival order). Damage: every cut position class, a bag never closed
(index_pos 0), a damaged index, hostile chunk sizes.
"""

from __future__ import annotations

import dataclasses
import random
import struct
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import lz4.frame
import numpy as np
import pytest
from rosbags.rosbag1 import Reader, Writer
from rosbags.typesys.store import Typestore

from lz4_layouts import LZ4_LAYOUTS
from syncaudit.errors import LogReadError, SyncauditError
from syncaudit.logs import open_log
from syncaudit.logs.model import ChannelInfo, ReadUnit
from syncaudit.logs.ros1.format import Rosbag1ChunkReader
from syncaudit.logs.ros1.reader import Rosbag1Log

OUSTER_BAG = "ouster_os1_512x10/512x10_raw.bag"
Untouched = Callable[[Path], Path]
Message = tuple[str, int, bytes]  # topic, log time, bytes
COMPRESSIONS = ["none", "bz2", "lz4"]


def reference(path: Path, topics: set[str] | None = None) -> list[Message]:
    """Every message as rosbags reads it (its index, merged by log time)."""
    with Reader(path) as bag:
        conns = [c for c in bag.connections if topics is None or c.topic in topics]
        if not conns:
            return []
        return [(c.topic, t, bytes(d)) for c, t, d in bag.messages(conns)]


def ours(path: Path, *args: object) -> list[Message]:
    with open_log(path) as log:
        assert isinstance(log, Rosbag1Log)
        return [(m.topic, m.log_time_ns, bytes(m.data)) for m in log.messages(*args)]  # type: ignore[arg-type]


def write_bag(path: Path, store: Typestore, compression: str, count: int = 300) -> Path:
    """A bag with /a (two connections: two nodes), /b and /c, small chunks, unordered times."""
    writer = Writer(path)
    if compression != "none":
        writer.set_compression(getattr(Writer.CompressionFormat, compression.upper()))
    writer.chunk_threshold = 2_500
    string = store.types["std_msgs/msg/String"]
    with writer:
        a1 = writer.add_connection("/a", "std_msgs/msg/String", typestore=store, callerid="/n1")
        a2 = writer.add_connection("/a", "std_msgs/msg/String", typestore=store, callerid="/n2")
        b = writer.add_connection("/b", "std_msgs/msg/String", typestore=store)
        c = writer.add_connection("/c", "std_msgs/msg/String", typestore=store, latching=1)
        writer.write(
            c, 999_000_000, store.serialize_ros1(string(data="latched"), string.__msgtype__)
        )
        for i in range(count):
            conn = (a1, a2, b)[i % 3]
            # every 5th message arrives late (a stamp 3..40 us earlier than its neighbours)
            t = 1_000_000_000 + i * 10_000 - (3_000 + (i * 7919) % 37_000) * (i % 5 == 0)
            text = f"{i}:" + "x" * (i % 50)
            writer.write(conn, t, store.serialize_ros1(string(data=text), string.__msgtype__))
    return path


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory, ros1_store: Typestore) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("ros1")
    return {c: write_bag(folder / f"{c}.bag", ros1_store, c) for c in COMPRESSIONS}


@pytest.mark.parametrize("compression", COMPRESSIONS)
def test_same_messages_and_summary_as_rosbags(
    compression: str, bags: dict[str, Path], untouched: Untouched
) -> None:
    path = untouched(bags[compression])
    expected = reference(path)
    assert len(expected) == 301
    assert ours(path) == expected
    assert ours(path, ["/b"]) == reference(path, {"/b"})
    assert ours(path, ["/a", "/c"]) == reference(path, {"/a", "/c"})
    window = [m for m in expected if 1_000_500_000 <= m[1] < 1_001_700_000]
    assert ours(path, None, 1_000_500_000, 1_001_700_000) == window
    with open_log(path) as log, Reader(path) as ref:
        s = log.summary
        assert (s.container, s.message_count, s.start_ns, s.end_ns) == (
            "rosbag1",
            ref.message_count,
            ref.start_time,
            ref.end_time - 1,
        )
        assert {n: (t.msgtype, t.count, t.encoding) for n, t in log.topics.items()} == {
            n: (t.msgtype, t.msgcount, "ros1") for n, t in ref.topics.items()
        }
        assert not log.warnings
        every = log.read_units(frozenset({"/a", "/b", "/c"}))
        assert every is not None and len(every) == 10
        assert log.read_units(frozenset({"/c"})) == every[:1]  # only chunks holding the topic
        msg = next(iter(log.messages("/b")))
        assert log.deserialize(msg).data.startswith("2:")  # type: ignore[attr-defined]


def test_real_ouster_bag_matches_rosbags(lidar_data: Path, untouched: Untouched) -> None:
    path = untouched(lidar_data / OUSTER_BAG)
    expected = reference(path)
    assert len(expected) == 43
    assert ours(path) == expected
    with open_log(path) as log:
        assert {n: t.count for n, t in log.topics.items()} == {
            "/os_node0/imu_packets": 10,
            "/os_node0/lidar_packets": 32,
            "/os_node0/metadata": 1,
        }
        assert log.topics["/os_node0/lidar_packets"].msgtype == "ouster_ros/msg/PacketMsg"
        assert log.topics["/os_node0/lidar_packets"].has_definition


def _read_unit(
    source_units: tuple[ReadUnit, dict[int, ChannelInfo]],
) -> list[tuple[int, int, int, str, bytes]]:
    """One unit in a worker: (log time, unit offset, index, topic, bytes) of its messages."""
    unit, channels = source_units
    reader = Rosbag1ChunkReader()
    try:
        return [
            (t, unit.offset, i, channels[c].topic, bytes(p))
            for t, i, c, p in reader.messages(unit, channels)
        ]
    finally:
        reader.close()


def _merged(results: Iterator[list[tuple[int, int, int, str, bytes]]]) -> list[Message]:
    """The parent's merge: (log time, unit offset, index)."""
    rows = sorted(row for result in results for row in result)
    return [(topic, t, data) for t, _offset, _index, topic, data in rows]


@pytest.mark.parametrize("compression", ["lz4", "bz2"])
def test_units_read_serially_and_in_processes_equal_rosbags(
    compression: str, bags: dict[str, Path]
) -> None:
    path = bags[compression]
    topics = frozenset({"/a", "/c"})
    with open_log(path) as log:
        units = log.read_units(topics)
        channels = log.unit_channels(topics)
    assert units is not None and len(units) == 10
    assert all(u.kind == "rosbag1-chunk" and u.cost > 0 for u in units)
    assert {c.topic for c in channels.values()} == {"/a", "/c"} and len(channels) == 3
    expected = reference(path, set(topics))
    jobs = [(u, channels) for u in units]
    assert _merged(iter(map(_read_unit, jobs))) == expected
    with ProcessPoolExecutor(2) as pool:
        assert _merged(pool.map(_read_unit, jobs)) == expected


@pytest.mark.parametrize("compression", COMPRESSIONS)
def test_one_reader_for_every_unit_keeps_earlier_payloads_intact(
    compression: str, bags: dict[str, Path]
) -> None:
    """The reader reads each chunk into one reused buffer: payloads of earlier units, held
    as they were given (views, as the serial merge holds them), still equal rosbags'."""
    path = bags[compression]
    topics = frozenset({"/a", "/c"})
    with open_log(path) as log:
        units = log.read_units(topics)
        channels = log.unit_channels(topics)
    assert units is not None
    reader = Rosbag1ChunkReader()
    try:
        held = [
            (t, unit.offset, i, channels[c].topic, p)
            for unit in units
            for t, i, c, p in reader.messages(unit, channels)
        ]
        rows = sorted((t, o, i, topic, bytes(p)) for t, o, i, topic, p in held)
    finally:
        reader.close()
    assert [(topic, t, data) for t, _o, _i, topic, data in rows] == reference(path, set(topics))


def _cut_positions(size: int) -> list[int]:
    return sorted({*range(13, 4200, 397), *range(4200, size, 83), size - 1, size - 4})


@pytest.mark.parametrize("compression", COMPRESSIONS)
def test_cut_bag_reads_every_complete_message_before_the_cut(
    compression: str, bags: dict[str, Path], tmp_path: Path
) -> None:
    """A bag cut anywhere (a crash, a full disk): the messages read are the bag's messages,
    more the later the cut, all but the cut chunk's at one byte short; exit 3 only when
    nothing is readable."""
    raw = bags[compression].read_bytes()
    full = set(reference(bags[compression]))
    path = tmp_path / "cut.bag"
    previous = 0
    read_some = 0
    for cut in _cut_positions(len(raw)):
        path.write_bytes(raw[:cut])
        try:
            with open_log(path) as log:
                got = [(m.topic, m.log_time_ns, bytes(m.data)) for m in log.messages()]
                warnings = [w.message for w in log.warnings]
        except LogReadError as exc:
            assert "no complete message" in str(exc) or "no message" in str(exc), exc
            assert previous == 0, f"cut at {cut}: nothing read after {previous} at an earlier cut"
            continue
        read_some += 1
        assert set(got) <= full and len(got) == len(set(got))
        assert [m[1] for m in got] == sorted(m[1] for m in got)
        assert len(got) >= previous, f"cut at {cut} reads fewer than an earlier cut"
        previous = len(got)
        assert warnings == [
            f"{path}: ROS 1 bag cut off at byte {cut} (recording interrupted?); "
            f"reading the {len(got)} complete messages before the cut"
        ]
    assert read_some > 50
    assert previous == len(full)  # cut one byte into the index: every message


def test_cut_uncompressed_chunk_keeps_its_complete_messages(
    lidar_data: Path, tmp_path: Path
) -> None:
    """Inside an uncompressed chunk the cut loses only the message it splits."""
    raw = (lidar_data / OUSTER_BAG).read_bytes()
    expected = reference(lidar_data / OUSTER_BAG)
    path = tmp_path / "cut.bag"
    path.write_bytes(raw[: len(raw) // 2])
    got = ours(path)
    assert 0 < len(got) < len(expected)
    assert got == sorted(expected[: len(got)], key=lambda m: m[1])
    path.write_bytes(raw[: int(len(raw) * 0.99)])
    assert len(ours(path)) == 42


def _unindexed(raw: bytes) -> bytes:
    """The bag as a recorder that died leaves it: index_pos 0 in the header, no index."""
    at = raw.index(b"index_pos=") + len(b"index_pos=")
    (index_pos,) = struct.unpack_from("<Q", raw, at)
    out = bytearray(raw[:index_pos])
    out[at : at + 8] = bytes(8)
    return bytes(out)


@pytest.mark.parametrize("compression", COMPRESSIONS)
def test_bag_without_index_is_read_by_scanning_chunks(
    compression: str, bags: dict[str, Path], tmp_path: Path
) -> None:
    path = tmp_path / "open.bag"
    path.write_bytes(_unindexed(bags[compression].read_bytes()))
    assert ours(path) == reference(bags[compression])
    with open_log(path) as log:
        assert [w.code for w in log.warnings] == ["rosbag1-no-index"]
        assert "no index (the recording was not closed)" in log.warnings[0].message
        assert log.summary.message_count == 301
        assert log.topics["/a"].count == 200 and log.topics["/c"].count == 1


def test_damaged_index_falls_back_to_the_scan(bags: dict[str, Path], tmp_path: Path) -> None:
    raw = bytearray(bags["lz4"].read_bytes())
    (index_pos,) = struct.unpack_from("<Q", raw, raw.index(b"index_pos=") + 10)
    at = raw.index(b"ver=\x01\x00\x00\x00", index_pos) + 4  # the first chunk info's version
    raw[at] = 7
    path = tmp_path / "badindex.bag"
    path.write_bytes(bytes(raw))
    assert ours(path) == reference(bags["lz4"])
    with open_log(path) as log:
        assert [w.code for w in log.warnings] == ["rosbag1-no-index"]
        assert "its index is damaged (bad index record (chunk info version is not 1) at byte" in (
            log.warnings[0].message
        )


@pytest.mark.parametrize("size", [0xFFFFFFFF, 1 << 29])
def test_hostile_chunk_size_is_refused_before_allocating(
    bags: dict[str, Path], tmp_path: Path, size: int
) -> None:
    raw = bytearray(bags["lz4"].read_bytes())
    at = raw.index(b"size=") + 5
    raw[at : at + 4] = struct.pack("<I", size)
    path = tmp_path / "bomb.bag"
    path.write_bytes(bytes(raw))
    with pytest.raises(SyncauditError) as info, open_log(path) as log:
        list(log.messages())
    assert isinstance(info.value, LogReadError)
    assert str(info.value).startswith(f"{path}: ROS 1 chunk at byte 4109: chunk claims")
    assert "decompression bomb" in str(info.value)


def test_encrypted_bag_is_refused_in_one_line(bags: dict[str, Path], tmp_path: Path) -> None:
    """rosbag's AES encryptor plugin: chunks are ciphertext, so the bag cannot be opened."""
    raw = bytearray(bags["none"].read_bytes())
    (hlen,) = struct.unpack_from("<I", raw, 13)
    field = b"encryptor=rosbag/AesCbcEncryptor"
    header = bytes(raw[17 : 17 + hlen]) + struct.pack("<I", len(field)) + field
    (dlen,) = struct.unpack_from("<I", raw, 17 + hlen)
    record = struct.pack("<I", len(header)) + header + struct.pack("<I", dlen - 4 - len(field))
    rest = raw[17 + hlen + 4 + dlen :]
    path = tmp_path / "secret.bag"
    path.write_bytes(bytes(raw[:13]) + record + b" " * (dlen - 4 - len(field)) + rest)
    with pytest.raises(SyncauditError) as info:
        open_log(path)
    assert info.value.exit_code == 2
    assert str(info.value).startswith(
        f"{path}: ROS 1 bag is encrypted with rosbag/AesCbcEncryptor;"
    )


def _mutate(raw: bytes, rng: random.Random) -> bytes:
    """Bit flips and hostile 32-bit values (0, 2^31-1, 2^32-1, random) at random offsets."""
    out = bytearray(raw)
    for _ in range(rng.choice([1, 1, 3, 10])):
        at = rng.randrange(len(out))
        if rng.random() < 0.5:
            out[at] ^= 1 << rng.randrange(8)
        else:
            out[at : at + 4] = rng.choice(
                [bytes(4), b"\xff\xff\xff\x7f", b"\xff\xff\xff\xff", rng.randbytes(4)]
            )
    return bytes(out)


def test_mutated_bags_end_in_a_documented_error_or_a_read(
    bags: dict[str, Path], tmp_path: Path
) -> None:
    """Fixed-seed mutants of each fixture: read, or one SyncauditError line naming the file."""
    rng = random.Random(2024)
    path = tmp_path / "mutant.bag"
    outcomes: dict[str, int] = {}
    for _ in range(150):
        path.write_bytes(_mutate(bags[rng.choice(COMPRESSIONS)].read_bytes(), rng))
        try:
            with open_log(path) as log:
                for _msg in log.messages():
                    pass
            outcome = "read"
        except SyncauditError as exc:
            text = str(exc)
            assert text.startswith(str(path)) and "\n" not in text, text
            outcome = type(exc).__name__
        outcomes[outcome] = outcomes.get(outcome, 0) + 1
    assert outcomes.get("read", 0) > 50 and outcomes.get("LogReadError", 0) > 10, outcomes


# ---- lz4 chunks read lazily (stored blocks stay views of the mapped file) ----------------

LZ4_FRAMES = LZ4_LAYOUTS


def write_camera_bag(path: Path, store: Typestore, frame: dict[str, object]) -> Path:
    """JPEG-like images (incompressible, 150-250 KB) and small messages, in lz4 chunks
    framed by the LZ4 library as `frame` says (rosbags' default chunk size)."""
    rng = random.Random(13)
    writer = Writer(path)
    writer.set_compression(Writer.CompressionFormat.LZ4)
    writer.compressor = lambda data: lz4.frame.compress(data, **frame)  # type: ignore[method-assign]
    image_t = store.types["sensor_msgs/msg/CompressedImage"]
    header_t = store.types["std_msgs/msg/Header"]
    time_t = store.types["builtin_interfaces/msg/Time"]
    string_t = store.types["std_msgs/msg/String"]
    with writer:
        image = writer.add_connection("/cam/image", image_t.__msgtype__, typestore=store)
        meta = writer.add_connection("/cam/meta", string_t.__msgtype__, typestore=store)
        for i in range(30):
            t = 1_000_000_000 + i * 33_000_000
            pixels = np.frombuffer(rng.randbytes(rng.randrange(150_000, 250_000)), np.uint8)
            stamp = header_t(seq=i, stamp=time_t(sec=1, nanosec=i), frame_id="cam_optical")
            msg = image_t(header=stamp, format="jpeg", data=pixels)
            writer.write(image, t, store.serialize_ros1(msg, image_t.__msgtype__))
            text = string_t(data=f"exposure {i} " * 20)
            writer.write(meta, t + 1_000, store.serialize_ros1(text, string_t.__msgtype__))
    return path


@pytest.fixture(scope="module")
def camera_bags(tmp_path_factory: pytest.TempPathFactory, ros1_store: Typestore) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("ros1cam")
    return {n: write_camera_bag(folder / f"{n}.bag", ros1_store, f) for n, f in LZ4_FRAMES.items()}


def _unit_messages(path: Path, *, check_crc: bool = False, prefix_bytes: int = 0) -> list[Message]:
    """Every message through one chunk reader, merged as the parent merges units."""
    topics = frozenset({"/cam/image", "/cam/meta"})
    with open_log(path) as log:
        units = log.read_units(topics)
        channels = log.unit_channels(topics)
    assert units is not None
    channels = {
        c: dataclasses.replace(i, prefix_bytes=prefix_bytes if i.topic == "/cam/image" else 0)
        for c, i in channels.items()
    }
    reader = Rosbag1ChunkReader(check_crc=check_crc)
    try:
        rows = [
            (t, unit.offset, i, channels[c].topic, bytes(p))
            for unit in units
            for t, i, c, p in reader.messages(unit, channels)
        ]
    finally:
        reader.close()
    return _merged(iter([rows]))


@pytest.mark.parametrize("frame", sorted(LZ4_FRAMES))
def test_lz4_frames_of_every_writer_read_as_rosbags_reads_them(
    frame: str, camera_bags: dict[str, Path], untouched: Untouched
) -> None:
    path = untouched(camera_bags[frame])
    expected = reference(path)
    assert len(expected) == 60
    assert ours(path) == expected
    assert _unit_messages(path) == expected
    assert _unit_messages(path, check_crc=True) == expected
    # images wanted for their header only: just that prefix, of the same bytes
    prefixed = _unit_messages(path, prefix_bytes=64)
    assert prefixed == [(t, s, d[:64] if t == "/cam/image" else d) for t, s, d in expected]


def _chunk_spans(path: Path) -> list[tuple[int, int]]:
    """(offset, length) of every chunk record, from the index."""
    with open_log(path) as log:
        units = log.read_units(frozenset({"/cam/image", "/cam/meta"}))
    assert units is not None
    return [(u.offset, u.length) for u in units]


def _read_all(path: Path, *, check_crc: bool = False) -> str:
    """The one-line error reading every message of `path` through the chunk reader."""
    with pytest.raises(LogReadError) as info:
        _unit_messages(path, check_crc=check_crc)
    text = str(info.value)
    assert "\n" not in text
    return text


def test_damaged_lz4_chunks_name_the_file_and_the_chunk(
    camera_bags: dict[str, Path], tmp_path: Path
) -> None:
    raw = camera_bags["roslz4"].read_bytes()
    (offset, length), *_ = _chunk_spans(camera_bags["roslz4"])
    (hlen,) = struct.unpack_from("<I", raw, offset)
    frame_at = offset + 8 + hlen
    path = tmp_path / "damaged.bag"
    where = f"{path}: ROS 1 chunk at byte {offset}: lz4 data damaged: "

    # a block size past anything the frame allows
    bad = bytearray(raw)
    struct.pack_into("<I", bad, frame_at + 7, 0xFFFFFFFF)
    path.write_bytes(bytes(bad))
    assert _read_all(path).startswith(
        where + "block at byte 7 of 2147483647 bytes is over the frame's 1048576-byte maximum"
    )

    # a compressed block with garbage in it: it may still decode (to wrong records, which
    # the record walk refuses); with --check-crc the content checksum names it
    bad = bytearray(raw)
    bad[frame_at + 40 : frame_at + 80] = b"\xff" * 40
    path.write_bytes(bytes(bad))
    assert _read_all(path).startswith(f"{path}: ROS 1 chunk at byte {offset}: ")
    assert _read_all(path, check_crc=True).startswith(where)

    # a header checksum that does not match
    bad = bytearray(raw)
    bad[frame_at + 6] ^= 0xFF
    path.write_bytes(bytes(bad))
    assert _read_all(path).startswith(where + "frame header checksum does not match")

    # the content checksum is verified with --check-crc only (as MCAP chunk CRCs are)
    bad = bytearray(raw)
    bad[offset + length - 1] ^= 0xFF
    path.write_bytes(bytes(bad))
    assert _unit_messages(path) == reference(camera_bags["roslz4"])
    assert _read_all(path, check_crc=True).startswith(where)


def test_lz4_chunk_claiming_more_than_it_holds_is_refused(
    camera_bags: dict[str, Path], tmp_path: Path
) -> None:
    """A chunk `size` larger than its frame (a bomb would be the same, with a frame that
    holds more): decoding stops at the size, and the chunk is refused."""
    raw = bytearray(camera_bags["roslz4"].read_bytes())
    (offset, _length), *_ = _chunk_spans(camera_bags["roslz4"])
    at = raw.index(b"size=", offset) + 5
    (size,) = struct.unpack_from("<I", raw, at)
    for claimed, problem in [(size + 1, f"not {size + 1}"), (size - 1, f"{size - 1} bytes")]:
        struct.pack_into("<I", raw, at, claimed)
        path = tmp_path / "claims.bag"
        path.write_bytes(bytes(raw))
        text = _read_all(path)
        assert text.startswith(f"{path}: ROS 1 chunk at byte {offset}: lz4 data damaged: ")
        assert problem in text


def test_bag_cut_after_it_was_opened_is_a_read_error_not_a_crash(
    camera_bags: dict[str, Path], tmp_path: Path
) -> None:
    """Chunks are read in place as they are reached: a file that shrinks under the reader
    is a read error naming the chunk."""
    path = tmp_path / "shrinking.bag"
    path.write_bytes(camera_bags["rosbags"].read_bytes())
    with open_log(path) as log, pytest.raises(LogReadError) as info:
        with path.open("r+b") as handle:
            handle.truncate(path.stat().st_size // 2)
        for _msg in log.messages():
            pass
    assert str(info.value).startswith(f"{path}: ROS 1 chunk at byte ")
    assert "file changed since it was opened?" in str(info.value)


def _reorder_message_headers(raw: bytes, order: tuple[str, str, str]) -> bytes:
    """Every 38-byte message header rewritten with its fields in `order` (rosbag writes
    them sorted by name; rosbags op first): the same record lengths, so the index holds."""
    out = bytearray(raw)
    start = b"\x26\x00\x00\x00\x04\x00\x00\x00op=\x02"
    at = out.find(start)
    count = 0
    while at >= 0:
        header = bytes(out[at + 4 : at + 42])
        fields = {}
        pos = 0
        while pos < len(header):
            (n,) = struct.unpack_from("<I", header, pos)
            field = header[pos : pos + 4 + n]
            fields[field[4:].split(b"=", 1)[0].decode()] = field
            pos += 4 + n
        out[at + 4 : at + 42] = b"".join(fields[name] for name in order)
        count += 1
        at = out.find(start, at + 42)
    assert count == 301
    return bytes(out)


@pytest.mark.parametrize("order", [("conn", "op", "time"), ("time", "conn", "op")])
def test_message_header_fields_in_any_order(
    order: tuple[str, str, str], bags: dict[str, Path], tmp_path: Path
) -> None:
    path = tmp_path / "ordered.bag"
    path.write_bytes(_reorder_message_headers(bags["none"].read_bytes(), order))
    expected = reference(bags["none"])
    assert reference(path) == expected  # rosbags reads fields by name, in any order
    assert ours(path) == expected


def _frame_targets(raw: bytes, spans: list[tuple[int, int]]) -> list[int]:
    """Offsets of what a damaged lz4 chunk gets wrong: chunk headers, frame descriptors,
    block sizes and the first bytes of each block."""
    out: list[int] = []
    for offset, length in spans:
        (hlen,) = struct.unpack_from("<I", raw, offset)
        frame = offset + 8 + hlen
        out += range(offset, frame + 20)
        pos = frame + 7 + (8 if raw[frame + 4] & 0x08 else 0)
        while pos < offset + length - 4:
            (word,) = struct.unpack_from("<I", raw, pos)
            if word == 0:
                break
            out += (pos, pos + 1, pos + 3, pos + 4, pos + 40)
            pos += 4 + (word & 0x7FFFFFFF) + (4 if raw[frame + 4] & 0x10 else 0)
    return out


def test_mutated_lz4_frames_end_in_a_read_error_or_a_read(
    camera_bags: dict[str, Path], tmp_path: Path
) -> None:
    """Hostile values in chunk headers, frame descriptors and block sizes: read, or one
    LogReadError line naming the file, with and without --check-crc; never a traceback."""
    rng = random.Random(7)
    path = tmp_path / "mutant.bag"
    outcomes: dict[str, int] = {}
    for name in ("roslz4", "rosbags"):
        raw = camera_bags[name].read_bytes()
        targets = _frame_targets(raw, _chunk_spans(camera_bags[name]))
        for _ in range(30):
            bad = bytearray(raw)
            at = rng.choice(targets)
            bad[at : at + 4] = rng.choice(
                [bytes(4), b"\xff\xff\xff\x7f", b"\xff\xff\xff\xff", b"\x00\x00\x01\x80"]
            )
            path.write_bytes(bytes(bad))
            for check_crc in (False, True):
                try:
                    _unit_messages(path, check_crc=check_crc)
                    outcome = "read"
                except SyncauditError as exc:
                    text = str(exc)
                    assert text.startswith(str(path)) and "\n" not in text, text
                    outcome = type(exc).__name__
                outcomes[outcome] = outcomes.get(outcome, 0) + 1
    assert outcomes.get("LogReadError", 0) > 40, outcomes


def test_check_crc_reaches_the_chunk_reader_of_the_workers(bags: dict[str, Path]) -> None:
    """`--check-crc` (the workers' `open_unit_reader(..., check_crc=True)`) switches the
    ROS 1 chunk reader to the checksum-verifying frame decoder."""
    from syncaudit.logs.unit_readers import open_unit_reader

    for check_crc in (False, True):
        reader = open_unit_reader("rosbag1-chunk", str(bags["lz4"]), check_crc=check_crc)
        try:
            assert isinstance(reader, Rosbag1ChunkReader) and reader.check_crc is check_crc
        finally:
            reader.close()
