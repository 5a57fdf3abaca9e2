"""rosbag2 SQLite storage (`.db3`): read-only, rows by rowid ranges.

The file is opened, checked and planned with the stdlib `sqlite3`; the rows are read with
`apsw` (see `SqliteRowsReader`).

Tables (rosbag2_storage_default_plugins, schema versions 1-4): `topics(id, name, type,
serialization_format, ...)`, `messages(id INTEGER PRIMARY KEY, topic_id, timestamp, data)`,
from schema 4 `message_definitions(topic_type, encoding, encoded_message_definition, ...)`.

A file is opened as `file:PATH?mode=ro&immutable=1`: sqlite neither writes nor creates a
journal, `-wal` or `-shm` beside it (rosbags opens it the same way). The messages of the
audited topics are split into 'sqlite-rows' units, ranges of rowid holding about
`WORKER_UNIT_BYTES` of payload, that workers read on their own (`UNIT_BYTES` for the serial
reader); rowid order is the recorder's write order, and log-time order within a unit is
restored by sorting (timestamp, rowid), the order of rosbag2's `ORDER BY timestamp` through
its timestamp index. A rowid range is one b-tree search and a scan, never a sort; the
timestamp index (the only one rosbag2 writes) is not used: following it reads the rows in
time order, all over the file.

A damaged or truncated file raises sqlite's "database disk image is malformed" where the
damage is reached: the rows are then read in rowid order up to it ("salvage"), and only
those rows are in the units.
"""

from __future__ import annotations

import sqlite3
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import quote

import apsw
import zstandard

from syncaudit.errors import LogOpenError, LogReadError
from syncaudit.logs.magic import ZSTD_MAGIC
from syncaudit.logs.model import ChannelInfo, ReadUnit
from syncaudit.logs.typesys import one_line

UNIT_KIND = "sqlite-rows"
UNIT_BYTES = 1 << 20
"""Payload bytes per unit of the serial reader (`SqliteLog.messages`), which holds a unit
at a time: like a ROS 1 chunk (768 KiB), so its memory stays flat."""
WORKER_UNIT_BYTES = 16 << 20
"""Payload bytes (images counted whole) per unit of `read_units`, whose reader streams its
rows: a unit costs ~19 us (its query, its set-up); reading the 2 GB benchmark bag took 0.18
s of CPU in 1 MiB units (2,693), 0.14 in 4 MiB (539), 0.13 in 16 MiB (130). collect groups
units into tasks of GROUP_BYTES (8 MB) by their cost."""
INLINE_BYTES = 16 * 1024
"""Wanted payloads up to this size are read with their rows; bigger ones through blob I/O,
whose opening (~3 us) costs less than a second copy of them."""
"""A zstd frame: the payload of a bag with compression_mode 'message' (a CDR payload begins
with its encapsulation header 00 0x 00 00, never with 0x28). Told by the payload, so a
worker needs nothing but the unit; rosbags decides by the metadata's compression_mode."""
MAX_MESSAGE_BYTES = 1 << 30
TAIL_ROWS = 256
"""Salvaged rows of a cut-off file checked for bytes from beyond the cut."""


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
    salvaged_rows: list[tuple[int, int, int, int]] = field(default_factory=list)
    """(rowid, topic id, timestamp, payload bytes) of the rows salvaged, in rowid order."""
    rowids: dict[int, tuple[int, int, int]] = field(default_factory=dict)
    """Topic id -> (first rowid, last rowid, payload bytes) of its rows (a whole file)."""


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
    path: Path,
    *,
    shown_as: Path | None = None,
    salvage: bool = False,
    tail: dict[int, int] | None = None,
) -> tuple[sqlite3.Connection, SqliteFile]:
    """Open `path` and read its topics and per-topic counts.

    LogOpenError where it is no rosbag2 database, SqliteDamagedError where its schema cannot
    be read; a database whose message rows are damaged is read in rowid order up to the
    damage (`damage`, `salvaged_until` set). `shown_as`: the name used in messages (the input
    a temporary copy was made of); `salvage`: read only what a rowid scan reaches; `tail`:
    gets the crc32 of the last salvaged payloads.
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
        # the inner query (kept apart by LIMIT -1) hands the grouping only the blob's length
        # (read from the record header): grouped directly, sqlite would copy every whole
        # payload into its sorter
        for topic_id, count, lo, hi, first, last, size in db.execute(
            "SELECT topic_id, COUNT(*), MIN(timestamp), MAX(timestamp), MIN(id), MAX(id), "
            "SUM(n) FROM (SELECT topic_id, timestamp, id, length(data) AS n FROM messages "
            "LIMIT -1) GROUP BY topic_id"
        ):
            if isinstance(topic_id, int) and isinstance(lo, int) and isinstance(hi, int):
                stats[topic_id] = (int(count), lo, hi)
                info.rowids[topic_id] = (int(first), int(last), int(size or 0))
    except sqlite3.DatabaseError as exc:
        info.damage = one_line(exc)
        stats, info.salvaged_until = _salvage_stats(db, info.salvaged_rows, tail)
    for topic_id, name, msgtype, fmt in rows:
        if not isinstance(topic_id, int) or name is None or msgtype is None:
            continue  # a topics row without id, name or type: nothing can be said of it
        count, lo, hi = stats.get(topic_id, (0, None, None))
        info.topics[int(topic_id)] = SqliteTopic(
            int(topic_id), str(name), str(msgtype), "" if fmt is None else str(fmt), count, lo, hi
        )
    return db, info


def _salvage_stats(
    db: sqlite3.Connection, rows: list[tuple[int, int, int, int]], tail: dict[int, int] | None
) -> tuple[dict[int, tuple[int, int | None, int | None]], int]:
    """Per-topic (count, first, last) of the rows readable in rowid order before the damage.

    Each payload is read whole, so a row whose overflow pages are lost ends the salvage
    before it, not in a worker. `tail`: filled with the crc32 of the last TAIL_ROWS payloads
    (for the check of a padded copy, see `verify_tail`).
    """
    stats: dict[int, list[int]] = {}
    last = -1
    column = "data" if tail is not None else "substr(data, -1)"
    try:
        cursor = db.execute(
            f"SELECT id, topic_id, timestamp, length(data), {column} FROM messages ORDER BY id"
        )
        for rowid, topic_id, t, size, payload in cursor:
            if not isinstance(topic_id, int) or not isinstance(t, int):
                break  # a row whose fields are not what rosbag2 writes: damage
            rows.append((int(rowid), topic_id, t, int(size or 0)))
            if tail is not None:
                tail[int(rowid)] = zlib.crc32(payload if isinstance(payload, bytes) else b"")
                if len(tail) > TAIL_ROWS:
                    del tail[next(iter(tail))]
            entry = stats.setdefault(topic_id, [0, t, t])
            entry[0] += 1
            entry[1] = min(entry[1], t)
            entry[2] = max(entry[2], t)
            last = int(rowid)
    except sqlite3.DatabaseError:
        pass
    return {k: (v[0], v[1], v[2]) for k, v in stats.items()}, last + 1


def verify_tail(path: Path, info: SqliteFile, tail: dict[int, int], real_bytes: int) -> None:
    """Drop the salvaged rows that took bytes from the padding of a cut-off file's copy.

    The copy was padded with 0xFF; the padding is now rewritten with zeros and the last
    payloads read again: a row whose bytes changed reached past the cut (a payload's last
    overflow page may lie there, and sqlite does not notice). Pages are allocated as rows are
    appended, so only the last rows can be affected.
    """
    with path.open("r+b") as handle:
        handle.seek(real_bytes)
        missing = path.stat().st_size - real_bytes
        block = bytes(min(missing, 1 << 20))
        while missing > 0:
            missing -= handle.write(block[:missing])
    bad: int | None = None
    db = connect(path)
    try:
        for rowid, crc in tail.items():
            try:
                row = db.execute("SELECT data FROM messages WHERE id = ?", (rowid,)).fetchone()
            except sqlite3.DatabaseError:
                row = None
            payload = row[0] if row is not None and isinstance(row[0], bytes) else None
            if payload is None or zlib.crc32(payload) != crc:
                bad = rowid
                break
    finally:
        db.close()
    if bad is None:
        return
    info.salvaged_rows = [r for r in info.salvaged_rows if r[0] < bad]
    info.salvaged_until = bad
    stats: dict[int, list[int]] = {}
    for _rowid, topic_id, t, _size in info.salvaged_rows:
        entry = stats.setdefault(topic_id, [0, t, t])
        entry[0] += 1
        entry[1] = min(entry[1], t)
        entry[2] = max(entry[2], t)
    for topic_id, topic in list(info.topics.items()):
        got = stats.get(topic_id)
        info.topics[topic_id] = SqliteTopic(
            topic.topic_id,
            topic.name,
            topic.msgtype,
            topic.serialization_format,
            got[0] if got else 0,
            got[1] if got else None,
            got[2] if got else None,
        )


def plan_units(
    db: sqlite3.Connection, info: SqliteFile, topic_ids: list[int], unit_bytes: int
) -> list[ReadUnit]:
    """Rowid ranges of about `unit_bytes` of the topics' payload, with their time spans.

    One aggregate query over fixed rowid buckets, sized from the per-topic rowids and bytes
    `open_sqlite` counted (sqlite reads a blob's length from its record header, not its
    pages); a salvaged file's units cover only the rows salvaged.
    """
    if not topic_ids:
        return []
    if info.salvaged_until is not None:
        return _plan_salvaged(info, set(topic_ids), unit_bytes)
    spans = [info.rowids[i] for i in topic_ids if i in info.rowids]
    if not spans:
        return []
    first = min(s[0] for s in spans)
    last = max(s[1] for s in spans)
    total = sum(s[2] for s in spans)
    count = sum(info.topics[i].count for i in topic_ids if i in info.rowids)
    marks = ",".join("?" * len(topic_ids))
    bytes_per_row = max(total / max(count, 1), 1.0)
    rows_per_unit = max(1, int(unit_bytes / bytes_per_row))
    span_per_row = (last - first + 1) / max(count, 1)  # rowids per wanted row (others between)
    step = max(1, int(rows_per_unit * span_per_row))
    units: list[ReadUnit] = []
    # the inner query (kept apart by LIMIT -1) hands the grouping only the blob's length:
    # grouped directly, sqlite copies each whole payload into its sorter (7 s for 760 MB)
    for _bucket, lo, hi, t0, t1, size in db.execute(
        "SELECT b, MIN(id), MAX(id), MIN(timestamp), MAX(timestamp), SUM(n) FROM ("
        "SELECT (id - ?) / ? AS b, id, timestamp, length(data) AS n "
        f"FROM messages WHERE id >= ? AND id <= ? AND topic_id IN ({marks}) LIMIT -1) "
        "GROUP BY b ORDER BY b",
        [first, step, first, last, *topic_ids],
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


def _plan_salvaged(info: SqliteFile, topic_ids: set[int], unit_bytes: int) -> list[ReadUnit]:
    """Units over the rows a salvage scan reached (sqlite must not step past them)."""
    units: list[ReadUnit] = []
    group: list[tuple[int, int, int, int]] = []
    size = 0

    def flush() -> None:
        units.append(
            ReadUnit(
                source=str(info.path),
                kind=UNIT_KIND,
                offset=group[0][0],
                length=group[-1][0] + 1,
                start_ns=min(r[2] for r in group),
                end_ns=max(r[2] for r in group),
                cost=size,
            )
        )

    for row in info.salvaged_rows:
        if row[1] not in topic_ids:
            continue
        group.append(row)
        size += row[3]
        if size >= unit_bytes:
            flush()
            group, size = [], 0
    if group:
        flush()
    return units


_AS_BYTES = "CASE WHEN typeof({0}) = 'text' THEN CAST({0} AS BLOB) ELSE {0} END"
"""A column as stored, but text as its bytes (apsw refuses text that is no UTF-8)."""


class _RowsFile:
    """One .db3 as a worker reads its rows: an apsw connection, the file's topic ids, and a
    blob handle moved from row to row (`sqlite3_blob_reopen`, which the stdlib lacks)."""

    __slots__ = ("blob", "db", "topics")

    def __init__(self, db: apsw.Connection, topics: dict[int, tuple[str, str]]) -> None:
        self.db = db
        self.topics = topics
        self.blob: apsw.Blob | None = None

    def close(self) -> None:
        if self.blob is not None:  # force: a blob that met damage re-raises it on close
            self.blob.close(True)
            self.blob = None
        self.db.close(True)


def _blob_bytes(rows: _RowsFile, rowid: int, size: int) -> object:
    """A row's payload through sqlite's incremental blob I/O: its first `size` bytes (all of
    it where `size` <= 0, or where a prefix cannot do: a zstd-compressed payload); a value
    that is no blob or text (NULL, a number) as the plain query gives it.

    Blob I/O reads a prefix from the blob's first page, never its overflow chain (a query's
    column is read whole, even under substr()), and copies a whole payload straight into the
    bytes returned (a column is first assembled in a buffer of sqlite's, then copied).
    """
    try:
        if rows.blob is None:
            rows.blob = rows.db.blob_open("main", "messages", "data", rowid, False)
        else:
            rows.blob.reopen(rowid)
    except apsw.SQLError:  # "cannot open value of type null/integer/real"
        if rows.blob is not None:  # a failed reopen leaves the handle unusable
            rows.blob.close(True)
            rows.blob = None
        for (value,) in rows.db.execute("SELECT data FROM messages WHERE id = ?", (rowid,)):
            return value
        return None
    blob = rows.blob
    if size <= 0:
        return blob.read()
    head = blob.read(size)
    if head[:4] == ZSTD_MAGIC:  # message-compressed: only the whole frame decodes
        return head + blob.read()
    return head


def _open_rows(path: Path) -> apsw.Connection:
    """`path` opened for its rows with apsw (read-only, immutable, as `connect`)."""
    uri = f"file:{quote(str(path.resolve()))}?mode=ro&immutable=1"
    return apsw.Connection(uri, flags=apsw.SQLITE_OPEN_READONLY | apsw.SQLITE_OPEN_URI)


class SqliteRowsReader:
    """Per-worker reader of 'sqlite-rows' units: one read-only connection per file, reused.

    Rows are read with apsw, a dependency of rosbags: its SQLite (bundled, newer than most
    systems') reads overflow pages straight into the result, and its blob handles move
    from row to row; on the 2 GB benchmark bag a worker's reading takes 28% less CPU than
    with the stdlib's. Topic names come from the stdlib, as the parent read them.

    A worker knows channels by the bag-wide ids of `unit_channels`; each file's own topic ids
    are matched to them by (topic, type), so split bags whose files number topics
    differently read right.
    """

    def __init__(self, source: str | None = None) -> None:
        """`source` (optional): the file the worker will read; units of others work too."""
        del source  # files are opened when their first unit is read
        self._files: dict[str, _RowsFile] = {}
        self._zstd = zstandard.ZstdDecompressor()

    def _open(self, source: str) -> _RowsFile:
        cached = self._files.get(source)
        if cached is None:
            try:
                names = connect(Path(source))
                try:
                    topics = {
                        int(i): (str(n), str(t))
                        for i, n, t in names.execute("SELECT id, name, type FROM topics")
                    }
                finally:
                    names.close()
                db = _open_rows(Path(source))
            except (sqlite3.Error, apsw.Error) as exc:
                raise LogReadError(
                    f"{source}: cannot read the bag database: {one_line(exc)}"
                ) from exc
            cached = self._files[source] = _RowsFile(db, topics)
        return cached

    def messages(
        self, unit: ReadUnit, channels: dict[int, ChannelInfo]
    ) -> Iterator[tuple[int, int, int, bytes | memoryview]]:
        """(log_time_ns, rowid - first rowid, channel id, payload) of wanted rows, rowid order."""
        rows = self._open(unit.source)
        by_name = {(c.topic, c.msgtype): cid for cid, c in channels.items()}
        local = {
            tid: by_name[key] for tid, key in rows.topics.items() if key in by_name
        }  # file topic id -> channel id
        if not local:
            return
        # Small payloads of the wanted topics come with the rows; bigger ones, and those of
        # which only a prefix is wanted (images: their header), through blob I/O (see
        # `_blob_bytes`). typeof() and length() read only the record header; text (in any
        # column) comes as its bytes, since apsw raises on invalid UTF-8 where the stdlib's
        # reader in the parent replaces it; a text payload is decoded as the parent does. Every row of the range is stepped over, the payload only of
        # wanted ones; the LIMIT ends the scan on the unit's last row, so sqlite never steps
        # onto the row after it (which a cut-off file may not have).
        prefix = {tid: channels[cid].prefix_bytes for tid, cid in local.items()}
        whole = [tid for tid, n in prefix.items() if n <= 0]
        marks = ",".join("?" * len(whole))
        cursor = rows.db.execute(
            f"SELECT id, {_AS_BYTES.format('topic_id')}, {_AS_BYTES.format('timestamp')}, "
            "typeof(data), length(data), "
            f"CASE WHEN topic_id IN ({marks}) AND (typeof(data) <> 'blob' OR length(data) <= ?) "
            "THEN CASE WHEN typeof(data) = 'text' THEN CAST(data AS BLOB) ELSE data END END "
            "FROM messages WHERE id >= ? AND id < ? ORDER BY id LIMIT ?",
            [*whole, INLINE_BYTES, unit.offset, unit.length, unit.length - unit.offset],
        )
        decompress = self._zstd.decompress
        try:
            for rowid, topic_id, t, kind, size, data in cursor:
                if topic_id not in local:
                    continue
                if not isinstance(t, int):
                    raise LogReadError(
                        f"{unit.source}: bag database row {rowid} has timestamp {t!r}, "
                        "not an integer"
                    )
                if prefix[topic_id] > 0 or (kind == "blob" and size > INLINE_BYTES):
                    data = _blob_bytes(rows, rowid, prefix[topic_id])
                elif kind == "text":  # as the stdlib gives it: decoded, bad bytes replaced
                    data = str(data.decode("utf-8", "replace")).encode()
                    yield t, int(rowid) - unit.offset, local[topic_id], data
                    continue
                if not isinstance(data, bytes):
                    data = b"" if data is None else str(data).encode()
                elif data[:4] == ZSTD_MAGIC:
                    try:
                        data = decompress(data, max_output_size=MAX_MESSAGE_BYTES)
                    except zstandard.ZstdError as exc:
                        if channels[local[topic_id]].encoding == "cdr":
                            raise LogReadError(
                                f"{unit.source}: zstd message payload of row {rowid} "
                                f"damaged: {one_line(exc)}"
                            ) from exc
                        # not CDR (protobuf, json...): bytes that merely begin like a
                        # zstd frame are kept as they are
                yield t, int(rowid) - unit.offset, local[topic_id], data
        except (apsw.Error, UnicodeDecodeError) as exc:
            # UnicodeDecodeError: should text that is no UTF-8 reach apsw after all
            raise LogReadError(
                f"{unit.source}: bag database damaged in rows {unit.offset}..{unit.length - 1}: "
                f"{one_line(exc)}"
            ) from exc
        finally:
            cursor.close()

    def close(self) -> None:
        """Close the connections opened so far."""
        for rows in self._files.values():
            rows.close()
        self._files.clear()
