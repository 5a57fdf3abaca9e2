"""rosbag2 SQLite storage (`.db3`) with the stdlib `sqlite3`: read-only, rows by rowid ranges.

Tables (rosbag2_storage_default_plugins, schema versions 1-4): `topics(id, name, type,
serialization_format, ...)`, `messages(id INTEGER PRIMARY KEY, topic_id, timestamp, data)`,
from schema 4 `message_definitions(topic_type, encoding, encoded_message_definition, ...)`.

A file is opened as `file:PATH?mode=ro&immutable=1`: sqlite neither writes nor creates a
journal, `-wal` or `-shm` beside it (rosbags opens it the same way). The messages of the
audited topics are split into 'sqlite-rows' units, ranges of rowid holding about
`UNIT_BYTES` of payload, that workers read on their own; rowid order is the recorder's
write order, and log-time order within a unit is restored by sorting (timestamp, rowid),
the order of rosbag2's `ORDER BY timestamp` through its timestamp index.

A damaged or truncated file raises sqlite's "database disk image is malformed" where the
damage is reached: the rows are then read in rowid order up to it ("salvage"), and only
those rows are in the units.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import quote

import zstandard

from syncaudit.errors import LogOpenError, LogReadError
from syncaudit.logs.model import ChannelInfo, ReadUnit
from syncaudit.logs.typesys import one_line

UNIT_KIND = "sqlite-rows"
UNIT_BYTES = 1 << 20
"""Payload bytes per unit: like a ROS 1 chunk (768 KiB), so the serial reader's memory stays
flat; collect groups units into bigger tasks by their cost."""
FETCH_ROWS = 64
ZSTD_MAGIC = b"\x28\xb5\x2f\xfd"
"""A zstd frame: the payload of a bag with compression_mode 'message' (a CDR payload begins
with its encapsulation header 00 0x 00 00, never with 0x28)."""
MAX_MESSAGE_BYTES = 1 << 30


def connect(path: Path) -> sqlite3.Connection:
    """Open a .db3 read-only and immutable (nothing is ever written beside it)."""
    uri = f"file:{quote(str(path.resolve()))}?mode=ro&immutable=1"
    db = sqlite3.connect(uri, uri=True, check_same_thread=False)
    db.text_factory = lambda raw: raw.decode("utf-8", "replace")
    return db


@dataclass(frozen=True, slots=True)
class SqliteTopic:
    """A row of the topics table, with what the messages table holds of it."""

    topic_id: int
    name: str
    msgtype: str
    serialization_format: str
    count: int
    start_ns: int | None
    end_ns: int | None


@dataclass(slots=True)
class SqliteFile:
    """One .db3 of a bag: its topics, definitions and the rowid range that is readable."""

    path: Path
    topics: dict[int, SqliteTopic]
    definitions: dict[str, tuple[str, str]]
    """Type name -> (encoding 'ros2msg'/'ros2idl', text), from schema 4 on."""
    damage: str | None = None
    """Where reading stopped ('' : whole file)."""
    salvaged_until: int | None = None
    """Rowid past the last row read before the damage (None: the file is whole)."""
    shown_as: Path | None = None
    """The input file where `path` is a temporary copy of it."""


class SqliteDamagedError(LogReadError):
    """The database's schema is unreadable (a file cut off, or damaged pages)."""


def declared_bytes(path: Path) -> int | None:
    """Size the database header says the file has (page size x page count), None if unknown."""
    try:
        with path.open("rb") as handle:
            head = handle.read(100)
    except OSError:
        return None
    if len(head) < 100:
        return None
    page = int.from_bytes(head[16:18], "big")
    page = 65536 if page == 1 else page
    pages = int.from_bytes(head[28:32], "big")
    if int.from_bytes(head[24:28], "big") != int.from_bytes(head[92:96], "big"):
        return None  # the page count is stale (sqlite's own rule): unknown
    return page * pages or None


def open_sqlite(
    path: Path, *, shown_as: Path | None = None, salvage: bool = False
) -> tuple[sqlite3.Connection, SqliteFile]:
    """Open `path` and read its topics and per-topic counts.

    LogOpenError where it is no rosbag2 database, SqliteDamagedError where its schema cannot
    be read; a database whose message rows are damaged is read in rowid order up to the
    damage (`damage`, `salvaged_until` set). `shown_as`: the name used in messages (the input
    a temporary copy was made of); `salvage`: read only what a rowid scan reaches.
    """
    name = shown_as or path
    try:
        db = connect(path)
    except sqlite3.Error as exc:
        raise LogOpenError(f"{name}: cannot open as a ROS 2 bag database: {one_line(exc)}") from exc
    try:
        tables = {r[0] for r in db.execute("SELECT name FROM sqlite_master WHERE type='table'")}
    except sqlite3.DatabaseError as exc:
        db.close()
        if "malformed" in str(exc) or "corrupt" in str(exc):
            raise SqliteDamagedError(
                f"{name}: ROS 2 bag database damaged or cut off ({one_line(exc)})"
            ) from exc
        raise LogOpenError(f"{name}: cannot open as a ROS 2 bag database: {one_line(exc)}") from exc
    if not {"messages", "topics"} <= tables:
        db.close()
        raise LogOpenError(f"{name}: SQLite file is not a ROS 2 bag (no messages/topics tables)")
    try:
        rows = db.execute("SELECT id, name, type, serialization_format FROM topics").fetchall()
        definitions: dict[str, tuple[str, str]] = {}
        if "message_definitions" in tables:
            for name, encoding, text in db.execute(
                "SELECT topic_type, encoding, encoded_message_definition FROM message_definitions"
            ):
                if name and text and name not in definitions:
                    definitions[str(name)] = (str(encoding), str(text))
    except sqlite3.Error as exc:
        db.close()
        raise SqliteDamagedError(
            f"{name}: ROS 2 bag topics table unreadable: {one_line(exc)}"
        ) from exc
    info = SqliteFile(path, {}, definitions)
    stats: dict[int, tuple[int, int | None, int | None]] = {}
    try:
        if salvage:
            raise sqlite3.DatabaseError("file ends before its declared size")
        for topic_id, count, lo, hi in db.execute(
            "SELECT topic_id, COUNT(*), MIN(timestamp), MAX(timestamp) FROM messages "
            "GROUP BY topic_id"
        ):
            stats[int(topic_id)] = (int(count), lo, hi)
    except sqlite3.DatabaseError as exc:
        info.damage = one_line(exc)
        stats, info.salvaged_until = _salvage_stats(db)
    for topic_id, name, msgtype, fmt in rows:
        count, lo, hi = stats.get(int(topic_id), (0, None, None))
        info.topics[int(topic_id)] = SqliteTopic(
            int(topic_id), str(name), str(msgtype), "" if fmt is None else str(fmt), count, lo, hi
        )
    return db, info


def _salvage_stats(
    db: sqlite3.Connection,
) -> tuple[dict[int, tuple[int, int | None, int | None]], int]:
    """Per-topic (count, first, last) of the rows readable in rowid order before the damage.

    Each payload is read whole (its last byte asked for), so a row whose overflow pages are
    lost ends the salvage before it, not in a worker.
    """
    stats: dict[int, list[int]] = {}
    last = -1
    try:
        cursor = db.execute(
            "SELECT id, topic_id, timestamp, substr(data, -1) FROM messages ORDER BY id"
        )
        for rowid, topic_id, t, _last_byte in cursor:
            entry = stats.setdefault(int(topic_id), [0, t, t])
            entry[0] += 1
            entry[1] = min(entry[1], t)
            entry[2] = max(entry[2], t)
            last = int(rowid)
    except sqlite3.DatabaseError:
        pass
    return {k: (v[0], v[1], v[2]) for k, v in stats.items()}, last + 1


def plan_units(db: sqlite3.Connection, info: SqliteFile, topic_ids: list[int]) -> list[ReadUnit]:
    """Rowid ranges of about UNIT_BYTES of the topics' payload, with their time spans.

    One aggregate query over fixed rowid buckets (sqlite reads a blob's length from its
    record header, not its pages); ranges outside the salvaged part are left out.
    """
    if not topic_ids:
        return []
    marks = ",".join("?" * len(topic_ids))
    limit = info.salvaged_until
    where = f"topic_id IN ({marks})" + (" AND id < ?" if limit is not None else "")
    args: list[int] = [*topic_ids, *([limit] if limit is not None else [])]
    row = db.execute(
        f"SELECT MIN(id), MAX(id), COUNT(*), SUM(length(data)) FROM messages WHERE {where}", args
    ).fetchone()
    if row is None or row[0] is None:
        return []
    first, last, count, total = (int(x or 0) for x in row)
    bytes_per_row = max(total / max(count, 1), 1.0)
    rows_per_unit = max(1, int(UNIT_BYTES / bytes_per_row))
    span_per_row = (last - first + 1) / max(count, 1)  # rowids per wanted row (others between)
    step = max(1, int(rows_per_unit * span_per_row))
    units: list[ReadUnit] = []
    for lo, hi, t0, t1, size in db.execute(
        "SELECT MIN(id), MAX(id), MIN(timestamp), MAX(timestamp), SUM(length(data)) "
        f"FROM messages WHERE {where} GROUP BY (id - ?) / ? ORDER BY 1",
        [*args, first, step],
    ):
        units.append(
            ReadUnit(
                source=str(info.path),
                kind=UNIT_KIND,
                offset=int(lo),
                length=int(hi) + 1,
                start_ns=int(t0),
                end_ns=int(t1),
                cost=int(size or 0),
            )
        )
    return units


class SqliteRowsReader:
    """Per-worker reader of 'sqlite-rows' units: one read-only connection per file, reused.

    A worker knows channels by the bag-wide ids of `unit_channels`; each file's own topic ids
    are matched to them by (topic, type), so split bags whose files number topics
    differently read right.
    """

    def __init__(self) -> None:
        self._files: dict[str, tuple[sqlite3.Connection, dict[int, tuple[str, str]]]] = {}
        self._zstd = zstandard.ZstdDecompressor()

    def _open(self, source: str) -> tuple[sqlite3.Connection, dict[int, tuple[str, str]]]:
        cached = self._files.get(source)
        if cached is None:
            try:
                db = connect(Path(source))
                topics = {
                    int(i): (str(n), str(t))
                    for i, n, t in db.execute("SELECT id, name, type FROM topics")
                }
            except sqlite3.Error as exc:
                raise LogReadError(
                    f"{source}: cannot read the bag database: {one_line(exc)}"
                ) from exc
            cached = self._files[source] = (db, topics)
        return cached

    def messages(
        self, unit: ReadUnit, channels: dict[int, ChannelInfo]
    ) -> Iterator[tuple[int, int, int, bytes | memoryview]]:
        """(log_time_ns, rowid - first rowid, channel id, payload) of wanted rows, rowid order."""
        db, topics = self._open(unit.source)
        by_name = {(c.topic, c.msgtype): cid for cid, c in channels.items()}
        local = {
            tid: by_name[key] for tid, key in topics.items() if key in by_name
        }  # file topic id -> channel id
        if not local:
            return
        marks = ",".join("?" * len(local))
        cursor = db.execute(
            "SELECT id, topic_id, timestamp, data FROM messages "
            f"WHERE id >= ? AND id < ? AND topic_id IN ({marks}) ORDER BY id",
            [unit.offset, unit.length, *local],
        )
        decompress = self._zstd.decompress
        try:
            while rows := cursor.fetchmany(FETCH_ROWS):
                for rowid, topic_id, t, data in rows:
                    if data is None:
                        data = b""
                    elif data[:4] == ZSTD_MAGIC:
                        data = decompress(data, max_output_size=MAX_MESSAGE_BYTES)
                    yield int(t), int(rowid) - unit.offset, local[topic_id], data
        except sqlite3.DatabaseError as exc:
            raise LogReadError(
                f"{unit.source}: bag database damaged in rows {unit.offset}..{unit.length - 1}: "
                f"{one_line(exc)}"
            ) from exc
        except zstandard.ZstdError as exc:
            raise LogReadError(
                f"{unit.source}: zstd message payload damaged in rows "
                f"{unit.offset}..{unit.length - 1}: {one_line(exc)}"
            ) from exc
        finally:
            cursor.close()

    def close(self) -> None:
        """Close the connections opened so far."""
        for db, _topics in self._files.values():
            db.close()
        self._files.clear()
