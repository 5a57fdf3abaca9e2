"""SQLite rosbag2 bags through our stdlib-sqlite3 reader, checked against rosbags' reader.

Also: the input is never written (no -wal/-shm/journal beside it), rowid-range units read
serially and in 2 processes give rosbags' messages, a cut .db3 is read up to the cut, and
metadata/topics-table quirks of other tools' bags (blank storage identifier, blank or
foreign serialization format) are read with a warning, never a dependency's message.
"""

from __future__ import annotations

import dataclasses
import itertools
import random
import shutil
import sqlite3
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import pytest
import yaml
from rosbags.rosbag2 import Reader, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode, StoragePlugin
from rosbags.typesys.store import Typestore

from syncaudit.errors import LogReadError, SyncauditError
from syncaudit.logs import open_log
from syncaudit.logs.model import ChannelInfo, ReadUnit
from syncaudit.logs.ros2 import sqlite_rows
from syncaudit.logs.ros2.sqlite_reader import SqliteLog
from syncaudit.logs.ros2.sqlite_rows import SqliteRowsReader

Untouched = Callable[[Path], Path]
Message = tuple[str, int, bytes]
VLP16_DIR = "velodyne_vlp16/1673400471837873222"
REAL = ["hesai_40p", "hesai_xt32", "velodyne_vlp16", "velodyne_vlp32"]


def reference(path: Path, topics: set[str] | None = None) -> list[Message]:
    with Reader(path) as bag:
        conns = [c for c in bag.connections if topics is None or c.topic in topics]
        return [(c.topic, t, bytes(d)) for c, t, d in bag.messages(conns)] if conns else []


def ours(path: Path, *args: Any) -> list[Message]:
    with open_log(path) as log:
        assert isinstance(log, SqliteLog)
        return [(m.topic, m.log_time_ns, bytes(m.data)) for m in log.messages(*args)]


def write_bag(
    path: Path,
    store: Typestore,
    *,
    count: int = 600,
    compression: CompressionMode = CompressionMode.NONE,
    storage: StoragePlugin = StoragePlugin.SQLITE3,
) -> Path:
    """/a, /b, /c Strings of 10..3000 bytes, every 7th stamped 0.5 ms earlier (late arrival),
    some stamps repeated across topics (ties are broken by rowid)."""
    writer = Writer(path, version=9, storage_plugin=storage)  # type: ignore[arg-type]
    writer.set_compression(compression, CompressionFormat.ZSTD)
    string = store.types["std_msgs/msg/String"]
    with writer:
        conns = [
            writer.add_connection(t, "std_msgs/msg/String", typestore=store)
            for t in ("/a", "/b", "/c")
        ]
        for i in range(count):
            t = 1_000_000 * (i // 2 + 1) - 500_000 * (i % 7 == 0)
            data = f"{i}:" + "y" * ((i * 37) % 3000)
            writer.write(
                conns[i % 3], t, store.serialize_cdr(string(data=data), string.__msgtype__)
            )
    return path


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory, ros2_store: Typestore) -> Path:
    return write_bag(tmp_path_factory.mktemp("sq") / "bag", ros2_store)


def _siblings(folder: Path) -> set[str]:
    return {p.name for p in folder.iterdir()}


@pytest.mark.parametrize("name", REAL)
def test_real_recordings_equal_rosbags(lidar_data: Path, name: str, untouched: Untouched) -> None:
    (meta,) = (lidar_data / name).glob("*/metadata.yaml")
    folder = untouched(meta.parent)
    (db3,) = folder.glob("*.db3")
    expected = reference(folder)
    assert expected
    assert ours(folder) == expected
    assert ours(db3) == expected
    assert _siblings(folder) == {"metadata.yaml", db3.name}


def test_written_bag_equals_rosbags_with_selections(bag: Path, untouched: Untouched) -> None:
    untouched(bag)
    expected = reference(bag)
    assert len(expected) == 600
    assert [t for _n, t, _d in expected] == sorted(t for _n, t, _d in expected)
    assert ours(bag) == expected
    assert ours(bag, ["/b", "/c"]) == reference(bag, {"/b", "/c"})
    assert ours(bag, None, 50_000_000, 120_000_000) == [
        m for m in expected if 50_000_000 <= m[1] < 120_000_000
    ]
    (db3,) = bag.glob("*.db3")
    assert ours(db3) == expected
    with open_log(bag) as log, Reader(bag) as ref:
        assert {n: (t.msgtype, t.count, t.encoding) for n, t in log.topics.items()} == {
            c.topic: (c.msgtype, c.msgcount, "cdr") for c in ref.connections
        }
        assert (log.summary.start_ns, log.summary.end_ns) == (ref.start_time, ref.end_time - 1)
        assert log.summary.container == "rosbag2-sqlite3" and not log.warnings
    assert _siblings(bag) == {"metadata.yaml", db3.name}  # no -wal, -shm or -journal


def _read_unit(
    job: tuple[ReadUnit, dict[int, ChannelInfo]],
) -> list[tuple[int, str, int, int, str, bytes]]:
    unit, channels = job
    reader = SqliteRowsReader()
    try:
        return [
            (t, unit.source, unit.offset, i, channels[c].topic, bytes(p))
            for t, i, c, p in reader.messages(unit, channels)
        ]
    finally:
        reader.close()


def _merged(results: Any) -> list[Message]:
    rows = sorted(row for result in results for row in result)
    return [(topic, t, data) for t, _s, _o, _i, topic, data in rows]


@pytest.mark.parametrize("compression", [CompressionMode.NONE, CompressionMode.MESSAGE])
def test_units_serially_and_in_two_processes_equal_rosbags(
    tmp_path: Path,
    ros2_store: Typestore,
    compression: CompressionMode,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    unit_bytes = 40_000 if compression == CompressionMode.NONE else 600  # zstd: ~20 B a row
    monkeypatch.setattr(sqlite_rows, "WORKER_UNIT_BYTES", unit_bytes)
    monkeypatch.setattr(sqlite_rows, "UNIT_BYTES", unit_bytes)
    path = write_bag(tmp_path / "bag", ros2_store, compression=compression)
    topics = frozenset({"/a", "/c"})
    with open_log(path) as log:
        units = log.read_units(topics)
        channels = log.unit_channels(topics)
    assert units is not None and len(units) > 5
    assert all(u.kind == "sqlite-rows" and u.offset < u.length and u.cost > 0 for u in units)
    assert [u.offset for u in units] == sorted(u.offset for u in units)
    assert all(a.length <= b.offset for a, b in itertools.pairwise(units))  # disjoint ranges
    expected = reference(path, set(topics))
    jobs = [(u, channels) for u in units]
    assert _merged(map(_read_unit, jobs)) == expected
    with ProcessPoolExecutor(2) as pool:
        assert _merged(pool.map(_read_unit, jobs)) == expected
    assert ours(path) == reference(path)


def test_cut_db3_reads_the_rows_before_the_cut(bag: Path, tmp_path: Path) -> None:
    (db3,) = bag.glob("*.db3")
    raw = db3.read_bytes()
    full = set(reference(bag))
    path = tmp_path / "cut.db3"
    read_some = 0
    for cut in [*range(0, len(raw), len(raw) // 25), len(raw) - 1]:
        path.write_bytes(raw[:cut])
        try:
            with open_log(path) as log:
                got = [(m.topic, m.log_time_ns, bytes(m.data)) for m in log.messages()]
                warnings = [w.message for w in log.warnings]
        except SyncauditError as exc:
            assert cut == 0 or isinstance(exc, LogReadError), exc
            assert str(exc).startswith(str(path)) and "\n" not in str(exc)
            continue
        read_some += 1
        assert got and set(got) <= full
        assert len(warnings) == 1 and warnings[0].startswith(
            f"{path}: ROS 2 bag database damaged or cut off (cut off at byte {cut}); "
            f"reading the {len(got)} messages before the damage"
        )
        assert _siblings(tmp_path) == {"cut.db3"}
    assert read_some >= 15


def test_damaged_page_reads_the_rows_before_it(bag: Path, tmp_path: Path) -> None:
    """A page of zeros in the middle (a bad sector): the rows before it, exit 0 with a warning."""
    (db3,) = bag.glob("*.db3")
    raw = bytearray(db3.read_bytes())
    page = 4096
    middle = (len(raw) // page // 2) * page
    raw[middle : middle + page] = bytes(page)
    path = tmp_path / "hole.db3"
    path.write_bytes(bytes(raw))
    try:
        with open_log(path) as log:
            got = [(m.topic, m.log_time_ns, bytes(m.data)) for m in log.messages()]
            codes = [w.code for w in log.warnings]
    except LogReadError as exc:  # the page held the schema of every row: nothing readable
        assert "no message can be read" in str(exc) or "damaged" in str(exc)
        return
    assert set(got) <= set(reference(bag)) and 0 < len(got) < 600
    assert codes == ["rosbag2-sqlite-damaged"]


def _copy(bag: Path, tmp_path: Path) -> Path:
    target = tmp_path / "copy"
    shutil.copytree(bag, target)
    for path in target.iterdir():
        path.chmod(0o644)
    return target


def _edit_meta(folder: Path, edit: Callable[[dict[str, Any]], None]) -> None:
    doc = yaml.safe_load((folder / "metadata.yaml").read_text())
    edit(doc["rosbag2_bagfile_information"])
    (folder / "metadata.yaml").write_text(yaml.safe_dump(doc))


@pytest.mark.parametrize("storage", [StoragePlugin.SQLITE3, StoragePlugin.MCAP])
def test_blank_storage_identifier_is_inferred(
    tmp_path: Path, ros2_store: Typestore, storage: StoragePlugin
) -> None:
    """`storage_identifier: ""` (some rosbag2 versions): the files' magic tells the storage."""
    bag = write_bag(tmp_path / "bag", ros2_store, count=30, storage=storage)
    expected = reference(bag)

    def blank(meta: dict[str, Any]) -> None:
        meta["storage_identifier"] = ""

    _edit_meta(bag, blank)
    with open_log(bag) as log:
        got = [(m.topic, m.log_time_ns, bytes(m.data)) for m in log.messages()]
        messages = [w.message for w in log.warnings]
    assert got == expected
    name = "sqlite3" if storage == StoragePlugin.SQLITE3 else "mcap"
    assert messages == [
        f"{bag}: metadata.yaml names storage ''; the files are {name} (read by their magic bytes)"
    ]


def test_blank_serialization_format_in_metadata_reads_as_cdr(
    tmp_path: Path, ros2_store: Typestore
) -> None:
    bag = write_bag(tmp_path / "bag", ros2_store, count=30)
    expected = reference(bag)

    def blank(meta: dict[str, Any]) -> None:
        for entry in meta["topics_with_message_count"]:
            entry["topic_metadata"]["serialization_format"] = ""

    _edit_meta(bag, blank)
    with open_log(bag) as log:
        assert {t.encoding for t in log.topics.values()} == {"cdr"}
        assert [(m.topic, m.log_time_ns, bytes(m.data)) for m in log.messages()] == expected
        assert [w.code for w in log.warnings] == ["rosbag2-empty-serialization"] * 3
        msg = next(iter(log.messages("/a")))
        assert log.deserialize(msg).data.startswith("0:")  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("fmt", "encoding"), [("", "cdr"), ("protobuf", "protobuf"), ("json", "json"), ("cdr2", "cdr2")]
)
def test_topics_table_serialization_format_is_reported_truthfully(
    tmp_path: Path, ros2_store: Typestore, fmt: str, encoding: str
) -> None:
    """A bare .db3 whose topics table says '' (read as cdr) or another encoding (reported)."""
    bag = write_bag(tmp_path / "bag", ros2_store, count=30)
    (db3,) = bag.glob("*.db3")
    with sqlite3.connect(db3) as db:
        db.execute("UPDATE topics SET serialization_format = ? WHERE name = '/b'", (fmt,))
    db.close()
    with open_log(db3) as log:
        assert log.topics["/b"].encoding == encoding
        assert log.topics["/a"].encoding == "cdr"
        got = [(m.topic, m.encoding) for m in log.messages("/b")]
        codes = [w.code for w in log.warnings]
    assert got == [("/b", encoding)] * 10
    assert codes == (["rosbag2-empty-serialization"] if fmt == "" else [])


def test_storage_cannot_be_told_is_one_line(tmp_path: Path, ros2_store: Typestore) -> None:
    bag = write_bag(tmp_path / "bag", ros2_store, count=3)
    (db3,) = bag.glob("*.db3")
    db3.write_bytes(b"not a database at all")
    db3.rename(bag / "data.bin")

    def blank(meta: dict[str, Any]) -> None:
        meta["storage_identifier"] = ""
        meta["relative_file_paths"] = ["data.bin"]

    _edit_meta(bag, blank)
    with pytest.raises(SyncauditError) as info:
        open_log(bag)
    text = str(info.value)
    assert info.value.exit_code == 2 and text.startswith(str(bag)) and "report" not in text
    assert "names storage '' and the files do not tell" in text


def test_wal_beside_the_database_is_reported_and_left_alone(
    bag: Path, tmp_path: Path, untouched: Untouched
) -> None:
    """A -wal left by a recorder that died is not read (immutable open) and not touched."""
    (db3,) = bag.glob("*.db3")
    folder = tmp_path / "w"
    folder.mkdir()
    copy = folder / "bag.db3"
    shutil.copyfile(db3, copy)
    (folder / "bag.db3-wal").write_bytes(b"\x37\x7f\x06\x82" + bytes(60))
    untouched(folder)
    with open_log(copy) as log:
        assert len(list(log.messages())) == 600
        assert [w.code for w in log.warnings] == ["rosbag2-wal-ignored"]
    assert _siblings(folder) == {"bag.db3", "bag.db3-wal"}


def test_split_bag_whose_files_number_topics_differently(
    tmp_path: Path, ros2_store: Typestore
) -> None:
    """rosbag2 numbers topics per file in order of first message: a topic's id differs
    between the files of a split bag; units and the serial read still give each its topic."""
    string = ros2_store.types["std_msgs/msg/String"]

    def part(name: str, order: tuple[str, ...], stamps: range) -> Path:
        with Writer(tmp_path / name, version=9) as writer:
            conns = {
                t: writer.add_connection(t, string.__msgtype__, typestore=ros2_store) for t in order
            }
            for i, t in enumerate(stamps):
                topic = order[i % len(order)]
                data = ros2_store.serialize_cdr(string(data=f"{topic}{t}"), string.__msgtype__)
                writer.write(conns[topic], t, data)
        return tmp_path / name

    first = part("p0", ("/a", "/b"), range(100, 200, 10))
    second = part("p1", ("/c", "/b", "/a"), range(195, 300, 7))
    bag = tmp_path / "split"
    bag.mkdir()
    doc = yaml.safe_load((first / "metadata.yaml").read_text())
    info = doc["rosbag2_bagfile_information"]
    counts: dict[str, int] = {}
    for folder in (first, second):
        (db3,) = folder.glob("*.db3")
        shutil.copyfile(db3, bag / f"{folder.name}.db3")
        meta = yaml.safe_load((folder / "metadata.yaml").read_text())
        for entry in meta["rosbag2_bagfile_information"]["topics_with_message_count"]:
            name = entry["topic_metadata"]["name"]
            counts[name] = counts.get(name, 0) + entry["message_count"]
            if name == "/c":
                info["topics_with_message_count"].append(entry)
    info["relative_file_paths"] = ["p0.db3", "p1.db3"]
    info.pop("files", None)
    for entry in info["topics_with_message_count"]:
        entry["message_count"] = counts[entry["topic_metadata"]["name"]]
    (bag / "metadata.yaml").write_text(yaml.safe_dump(doc))
    expected = sorted(reference(first) + reference(second), key=lambda m: m[1])
    for topic, _t, data in expected:  # every payload names its own topic
        assert topic.encode() in data
    assert ours(bag) == expected
    with open_log(bag) as log:
        assert {n: t.count for n, t in log.topics.items()} == counts
        units = log.read_units(frozenset({"/a", "/c"}))
        channels = log.unit_channels(frozenset({"/a", "/c"}))
    assert units is not None and {Path(u.source).name for u in units} == {"p0.db3", "p1.db3"}
    want = [m for m in expected if m[0] in {"/a", "/c"}]
    assert _merged(map(_read_unit, [(u, channels) for u in units])) == want


@pytest.mark.parametrize("compression", [CompressionMode.NONE, CompressionMode.MESSAGE])
def test_prefix_channels_give_the_payloads_first_bytes(
    tmp_path: Path, ros2_store: Typestore, compression: CompressionMode
) -> None:
    """A channel marked `prefix_bytes` (an image: only its header is read) gets the first
    bytes of each payload through blob I/O, a zstd-compressed one whole and decompressed;
    the other channels and every time and order are unchanged."""
    path = write_bag(tmp_path / "bag", ros2_store, compression=compression)
    topics = frozenset({"/a", "/b"})
    with open_log(path) as log:
        units = log.read_units(topics)
        channels = log.unit_channels(topics)
    assert units is not None
    marked = {
        cid: dataclasses.replace(info, prefix_bytes=16) if info.topic == "/a" else info
        for cid, info in channels.items()
    }
    whole = [row for u in units for row in _read_unit((u, channels))]
    short = [row for u in units for row in _read_unit((u, marked))]
    assert [r[:5] for r in short] == [r[:5] for r in whole]
    cut = compression == CompressionMode.NONE  # a zstd frame only decodes whole
    for (*_, topic, full), (*_, _topic, head) in zip(whole, short, strict=True):
        assert head == (full[:16] if topic == "/a" and cut else full)
    assert any(len(r[5]) > 16 for r in whole if r[4] == "/a")


def write_big_bag(path: Path, store: Typestore, compression: CompressionMode) -> Path:
    """/big payloads of 100 B to 60 KB (about two thirds over `INLINE_BYTES`, read by blob
    I/O), /small ones of 20-200 B between them; random bytes (seeded), so that zstd leaves
    the big ones big."""
    string = store.types["std_msgs/msg/String"].__msgtype__
    writer = Writer(path, version=9)
    writer.set_compression(compression, CompressionFormat.ZSTD)
    with writer:
        big = writer.add_connection("/big", string, typestore=store)
        small = writer.add_connection("/small", string, typestore=store)
        for i in range(60):
            size = 100 + (i * 7919) % 60_000
            writer.write(
                big, 1_000 * (i + 1), bytes([0, 1, 0, 0]) + random.Random(i).randbytes(size)
            )
            writer.write(small, 1_000 * (i + 1) + 500, bytes([0, 1, 0, 0, i]) * (4 + i % 40))
    return path


@pytest.mark.parametrize("compression", [CompressionMode.NONE, CompressionMode.MESSAGE])
def test_payloads_over_the_inline_size_come_whole_through_blob_io(
    tmp_path: Path,
    ros2_store: Typestore,
    compression: CompressionMode,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Payloads over `INLINE_BYTES` are read through blob I/O, smaller ones with their rows:
    units (serially and in two processes) and the serial reader give rosbags' bytes."""
    path = write_big_bag(tmp_path / "bag", ros2_store, compression)
    expected = reference(path)
    assert sum(len(d) > sqlite_rows.INLINE_BYTES for _t, _s, d in expected) > 15
    opened: list[int] = []
    blob_bytes = sqlite_rows._blob_bytes

    def counted(rows: Any, rowid: int, size: int) -> object:
        opened.append(rowid)
        return blob_bytes(rows, rowid, size)

    monkeypatch.setattr(sqlite_rows, "_blob_bytes", counted)
    monkeypatch.setattr(sqlite_rows, "WORKER_UNIT_BYTES", 200_000)
    topics = frozenset({"/big", "/small"})
    with open_log(path) as log:
        units = log.read_units(topics)
        channels = log.unit_channels(topics)
    assert units is not None and len(units) > 3
    jobs = [(u, channels) for u in units]
    assert _merged(map(_read_unit, jobs)) == expected
    with ProcessPoolExecutor(2) as pool:
        assert _merged(pool.map(_read_unit, jobs)) == expected
    assert ours(path) == expected
    stored = {
        rowid: size
        for rowid, size in sqlite3.connect(next(path.glob("*.db3"))).execute(
            "SELECT id, length(data) FROM messages"
        )
    }
    big = {r for r, n in stored.items() if n > sqlite_rows.INLINE_BYTES}
    assert big and set(opened) == big  # every big payload by blob I/O, nothing else


def test_values_that_are_no_blob_read_as_before(bag: Path, tmp_path: Path) -> None:
    """A row whose data is text or a number (no recorder writes one; a tool might): the
    text's UTF-8 (bytes that are no UTF-8 replaced, as the stdlib reads them; raw by
    prefix), the number's digits; blobs empty, above and below the inline size as stored.
    (rosbag2's schema says `data BLOB NOT NULL`.)"""
    (db3,) = bag.glob("*.db3")
    path = tmp_path / "odd.db3"
    shutil.copyfile(db3, path)
    big = b"\x00\x01\x00\x00" + bytes(range(256)) * 100
    values: list[object] = [b"", "t\u00e9xt", 1234, big, b"\x00\x01small", 0.1 / 3]
    with sqlite3.connect(path) as db:
        ids = [r[0] for r in db.execute("SELECT id FROM messages WHERE topic_id = 1 LIMIT 7")]
        for rowid, value in zip(ids, values, strict=False):
            db.execute("UPDATE messages SET data = ? WHERE id = ?", (value, rowid))
        db.execute("UPDATE messages SET data = CAST(x'ff41' AS TEXT) WHERE id = ?", (ids[6],))
    db.close()
    digits = str(0.1 / 3).encode()
    want = [b"", "t\u00e9xt".encode(), b"1234", big, b"\x00\x01small", digits, b"\xef\xbf\xbdA"]
    with open_log(path) as log:
        topic = log.unit_channels(frozenset({"/a"}))
        units = log.read_units(frozenset({"/a"}))
        serial = [bytes(m.data) for m in log.messages("/a")]
    assert units is not None
    whole = [row[5] for u in units for row in _read_unit((u, topic))]
    marked = {c: dataclasses.replace(i, prefix_bytes=8) for c, i in topic.items()}
    heads = [row[5] for u in units for row in _read_unit((u, marked))]
    assert whole[:7] == want and serial[:7] == want
    assert heads[:7] == [*want[:3], big[:8], want[4], digits, b"\xffA"]
    assert len(whole) == len(serial) == 200


@pytest.mark.parametrize("stamp", ["CAST(x'ff' AS TEXT)", "'soon'"])
def test_text_timestamp_is_one_line(bag: Path, tmp_path: Path, stamp: str) -> None:
    """A wanted row whose timestamp is text (UTF-8 or not) fails its unit with one line
    naming the file and row (exit 3); the same row in a topic not read is stepped over."""
    (db3,) = bag.glob("*.db3")
    path = tmp_path / "odd.db3"
    shutil.copyfile(db3, path)
    with open_log(path) as log:
        units = log.read_units(frozenset({"/a", "/b"}))
        channels = log.unit_channels(frozenset({"/a", "/b"}))
        only_a = log.unit_channels(frozenset({"/a"}))
    assert units is not None
    with sqlite3.connect(path) as db:
        (rowid,) = db.execute("SELECT id FROM messages WHERE topic_id = 2 LIMIT 1 OFFSET 50")
        db.execute(f"UPDATE messages SET timestamp = {stamp} WHERE id = ?", rowid)
    db.close()
    got = [row for u in units for row in _read_unit((u, only_a))]
    assert len(got) == 200 and {r[4] for r in got} == {"/a"}
    with pytest.raises(LogReadError) as info:
        for unit in units:
            _read_unit((unit, channels))
    text = str(info.value)
    assert (
        text.startswith(f"{path}: bag database row {rowid[0]} has timestamp ") and "\n" not in text
    )
    assert text.endswith("not an integer") and info.value.exit_code == 3


def test_damaged_overflow_page_of_a_big_payload_is_one_line(
    tmp_path: Path, ros2_store: Typestore
) -> None:
    """An overflow page of a payload read by blob I/O zeroed (a bad sector): the unit's read
    fails with one line naming the file and its rows (exit code 3), never a traceback."""
    path = write_big_bag(tmp_path / "bag", ros2_store, CompressionMode.NONE)
    (db3,) = path.glob("*.db3")
    payload = next(d for _t, _s, d in reference(path, {"/big"}) if len(d) > 50_000)
    raw = bytearray(db3.read_bytes())
    page = 4096
    at = raw.find(payload[30_000:30_100])  # in the middle of its overflow chain
    assert at > 0
    raw[at - at % page : at - at % page + page] = bytes(page)
    db3.write_bytes(bytes(raw))
    topics = frozenset({"/big"})
    with open_log(path) as log:
        units = log.read_units(topics)
        channels = log.unit_channels(topics)
    assert units is not None
    with pytest.raises(LogReadError) as info:
        for unit in units:
            _read_unit((unit, channels))
    text = str(info.value)
    assert text.startswith(f"{db3}: bag database damaged in rows ") and "\n" not in text
    assert info.value.exit_code == 3


def test_database_locked_by_a_writer_is_read_without_locking(
    tmp_path: Path, ros2_store: Typestore
) -> None:
    """A writer holding an exclusive lock (a recorder mid-transaction) does not block or fail
    the read: the file is opened immutable, so sqlite takes no lock; units (blob I/O for the
    big payloads too) and the serial reader give the committed rows."""
    path = write_big_bag(tmp_path / "bag", ros2_store, CompressionMode.NONE)
    expected = reference(path)
    (db3,) = path.glob("*.db3")
    writer = sqlite3.connect(db3, isolation_level=None, timeout=0)
    try:
        writer.execute("PRAGMA journal_mode=DELETE")
        writer.execute("BEGIN EXCLUSIVE")
        with pytest.raises(sqlite3.OperationalError, match="locked"):
            sqlite3.connect(db3, timeout=0).execute("SELECT COUNT(*) FROM messages").fetchone()
        topics = frozenset({"/big", "/small"})
        with open_log(path) as log:
            units = log.read_units(topics)
            channels = log.unit_channels(topics)
            assert ours(path) == expected
        assert units is not None
        assert _merged(map(_read_unit, [(u, channels) for u in units])) == expected
    finally:
        writer.execute("ROLLBACK")
        writer.close()
    assert _siblings(path) == {"metadata.yaml", db3.name}
