"""ROS 1 bags through our own reader, checked message by message against rosbags' reader.

Fixtures: the real Ouster bag (shared data) and bags written here with rosbags' Writer in
each chunk compression ROS 1 knows (none, bz2, lz4 frames), small chunks, several
connections, one topic recorded by two nodes, and log times out of order inside chunks (a
recorder writes in arrival order). Damage: every cut position class, a bag never closed
(index_pos 0), a damaged index, hostile chunk sizes.
"""

from __future__ import annotations

import random
import struct
from collections.abc import Callable, Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pytest
from rosbags.rosbag1 import Reader, Writer
from rosbags.typesys.store import Typestore

from syncaudit.errors import LogReadError, SyncauditError
from syncaudit.logs import open_log
from syncaudit.logs.model import ChannelInfo, ReadUnit
from syncaudit.logs.rosbag1 import Rosbag1ChunkReader
from syncaudit.logs.rosbag1_log import Rosbag1Log

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
