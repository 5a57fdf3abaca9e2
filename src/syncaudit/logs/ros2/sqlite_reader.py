"""ROS 2 bags with SQLite storage (a folder with metadata.yaml, or a bare `.db3`).

Opened and planned with the stdlib sqlite3; rows read with apsw (`sqlite_rows`).
"""

from __future__ import annotations

import shutil
import sqlite3
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from syncaudit.errors import LogOpenError, LogReadError
from syncaudit.logs.base import LogReader
from syncaudit.logs.model import ChannelInfo, LogSummary, RawMessage, ReadUnit, TopicInfo
from syncaudit.logs.ros2 import sqlite_rows
from syncaudit.logs.ros2.metadata import BagMetadata
from syncaudit.logs.ros2.sqlite_rows import (
    SqliteFile,
    SqliteRowsReader,
    connect,
    declared_bytes,
    open_sqlite,
    plan_units,
    verify_tail,
)
from syncaudit.logs.typesys import Definition, one_line
from syncaudit.logs.unit_merge import UnitMessage, merge_units, sorted_unit

if TYPE_CHECKING:
    pass


class SqliteLog(LogReader):
    """A rosbag2 SQLite bag: its files' topics merged by (name, type), rows read in units."""

    def __init__(self, path: Path, meta: BagMetadata | None = None) -> None:
        """`path`: a bare .db3 (meta None) or the bag folder whose metadata is `meta`."""
        self.path = path
        self.warnings = list(meta.warnings) if meta is not None else []
        self._tmpdir: Path | None = None
        self._dbs: list[sqlite3.Connection] = []
        self._files: list[SqliteFile] = []
        self._rows = SqliteRowsReader()
        try:
            for source in meta.files if meta is not None else [path]:
                if meta is not None and meta.compression_mode == "file":
                    source = self._decompressed(source)
                self._check_wal(source)
                db, info = self._open_file(source)
                self._dbs.append(db)
                self._files.append(info)
            self._channels = self._make_channels(meta)
            self.summary = self._make_summary()
            self._report_damage()
        except BaseException:
            self._close()
            raise

    # -- opening -----------------------------------------------------------------------------

    def _decompressed(self, source: Path) -> Path:
        """A zstd-compressed storage file ('file' compression mode) unpacked to a temporary
        file (sqlite needs a file; rosbags does the same); deleted on close."""
        import zstandard

        target = self._scratch() / source.name.removesuffix(".zstd")
        try:
            with source.open("rb") as src, target.open("wb") as out:
                zstandard.ZstdDecompressor().copy_stream(src, out)
        except (OSError, zstandard.ZstdError) as exc:
            raise LogReadError(f"{source}: zstd storage file unreadable: {one_line(exc)}") from exc
        return target

    def _open_file(self, source: Path) -> tuple[sqlite3.Connection, SqliteFile]:
        """Open one .db3; one cut off is read from a copy padded to its declared size."""
        declared = declared_bytes(source)
        if declared is None or declared <= source.stat().st_size:
            return open_sqlite(source)
        # sqlite refuses a schema whose tables start past the end of the file: pad a copy to
        # the declared size so the pages before the cut can be read. The padding is 0xFF, not
        # zeros: a zero page would pass for the last page of a payload's overflow chain (next
        # page 0) and hand up zeros as data; 0xFF names a page past the end (and is no valid
        # b-tree page type), which sqlite reports as damage.
        padded = self._scratch() / source.name
        try:
            shutil.copyfile(source, padded)
            with padded.open("ab") as out:
                missing = declared - source.stat().st_size
                block = b"\xff" * min(missing, 1 << 20)
                while missing > 0:
                    missing -= out.write(block[:missing])
        except OSError as exc:
            raise LogReadError(
                f"{source}: cut-off bag database could not be copied for reading: {one_line(exc)}"
            ) from exc
        tail: dict[int, int] = {}
        db, info = open_sqlite(padded, shown_as=source, salvage=True, tail=tail)
        db.close()  # reopened below: the padding is rewritten by the check
        try:
            verify_tail(padded, info, tail, source.stat().st_size)
            db = connect(padded)
        except (OSError, sqlite3.Error) as exc:
            raise LogReadError(
                f"{source}: cut-off bag database could not be checked: {one_line(exc)}"
            ) from exc
        info.damage = f"cut off at byte {source.stat().st_size}"
        info.shown_as = source
        return db, info

    def _scratch(self) -> Path:
        if self._tmpdir is None:
            self._tmpdir = Path(tempfile.mkdtemp(prefix="syncaudit-db3-"))
        return self._tmpdir

    def _check_wal(self, source: Path) -> None:
        wal = source.with_name(source.name + "-wal")
        if wal.is_file() and wal.stat().st_size > 0:
            self.warn(
                "rosbag2-wal-ignored",
                f"{source}: a write-ahead log {wal.name} lies beside it (recording not closed?); "
                "its rows are not read, since reading it would change the input",
            )

    def _make_channels(self, meta: BagMetadata | None) -> dict[int, ChannelInfo]:
        """One channel per (topic, type) across the files, numbered from 1 in file order."""
        formats = {t.name: t.serialization_format for t in meta.topics} if meta else {}
        channels: dict[int, ChannelInfo] = {}
        seen: dict[tuple[str, str], int] = {}
        for info in self._files:
            for topic in sorted(info.topics.values(), key=lambda t: t.topic_id):
                key = (topic.name, topic.msgtype)
                if key in seen:
                    continue
                encoding = formats.get(topic.name) or topic.serialization_format
                if not encoding:
                    self.warn(
                        "rosbag2-empty-serialization",
                        f"{info.path}: topic {topic.name} has an empty serialization_format in "
                        "its topics table; read as cdr (the only format rosbag2 writes)",
                    )
                    encoding = "cdr"
                seen[key] = len(seen) + 1
                channels[seen[key]] = ChannelInfo(topic.name, topic.msgtype, encoding)
        return channels

    def _make_summary(self) -> LogSummary:
        counts: dict[int, int] = {}
        starts: list[int] = []
        ends: list[int] = []
        ids = {(c.topic, c.msgtype): cid for cid, c in self._channels.items()}
        for info in self._files:
            for topic in info.topics.values():
                cid = ids[(topic.name, topic.msgtype)]
                counts[cid] = counts.get(cid, 0) + topic.count
                if topic.start_ns is not None and topic.end_ns is not None:
                    starts.append(int(topic.start_ns))
                    ends.append(int(topic.end_ns))
        total = sum(counts.values())
        summary = LogSummary(
            path=str(self.path),
            container="rosbag2-sqlite3",
            start_ns=min(starts) if total else None,
            end_ns=max(ends) if total else None,
            message_count=total,
        )
        defined = {name for info in self._files for name in info.definitions}
        for cid, channel in self._channels.items():
            prior = summary.topics.get(channel.topic)
            if prior is not None:
                self.warn(
                    "rosbag2-mixed-types",
                    f"{self.path}: topic {channel.topic} is recorded with types "
                    f"{prior.msgtype} and {channel.msgtype}; only {prior.msgtype} is read",
                )
                continue
            summary.topics[channel.topic] = TopicInfo(
                name=channel.topic,
                msgtype=channel.msgtype,
                encoding=channel.encoding,
                count=counts.get(cid, 0),
                has_definition=channel.msgtype in defined,
            )
        return summary

    def _report_damage(self) -> None:
        damaged = [f for f in self._files if f.damage is not None]
        if not damaged:
            return
        total = self.summary.message_count or 0
        for info in damaged:
            read = sum(t.count for t in info.topics.values())
            where = info.shown_as or info.path
            text = (
                f"{where}: ROS 2 bag database damaged or cut off ({info.damage}); reading "
                f"the {read} messages before the damage (rows below {info.salvaged_until})"
            )
            if total == 0:
                raise LogReadError(
                    f"{where}: ROS 2 bag database damaged or cut off ({info.damage}); "
                    "no message can be read"
                )
            self.warn("rosbag2-sqlite-damaged", text)

    # -- units -------------------------------------------------------------------------------

    def _wanted(self, topics: frozenset[str] | None) -> dict[int, ChannelInfo]:
        return {
            cid: c
            for cid, c in self._channels.items()
            if (topics is None or c.topic in topics)
            and self.summary.topics[c.topic].msgtype == c.msgtype
        }

    def read_units(self, topics: frozenset[str]) -> list[ReadUnit] | None:
        """Rowid ranges of about 1 MiB of the topics' payload, per file, in file order."""
        return self._units(self._wanted(topics), sqlite_rows.WORKER_UNIT_BYTES)

    def _units(self, channels: dict[int, ChannelInfo], unit_bytes: int) -> list[ReadUnit]:
        keys = {(c.topic, c.msgtype) for c in channels.values()}
        units: list[ReadUnit] = []
        for db, info in zip(self._dbs, self._files, strict=True):
            ids = [t.topic_id for t in info.topics.values() if (t.name, t.msgtype) in keys]
            try:
                units.extend(plan_units(db, info, ids, unit_bytes))
            except sqlite3.DatabaseError as exc:
                raise LogReadError(
                    f"{info.path}: bag database damaged while planning reads: {one_line(exc)}"
                ) from exc
        return units

    def unit_channels(self, topics: frozenset[str]) -> dict[int, ChannelInfo]:
        """Bag-wide channel id -> topic, type, serialization format for `topics`."""
        return self._wanted(topics)

    # -- serial reading ----------------------------------------------------------------------

    def _messages(
        self, topics: frozenset[str] | None, start_ns: int | None, stop_ns: int | None
    ) -> Iterator[RawMessage]:
        """Messages in (log time, rowid) order per file, files merged by log time."""
        channels = self._wanted(topics)
        if not channels:
            return
        units = [
            u
            for u in self._units(channels, sqlite_rows.UNIT_BYTES)
            if (start_ns is None or u.end_ns >= start_ns)
            and (stop_ns is None or u.start_ns < stop_ns)
        ]

        def read(unit: ReadUnit) -> Iterator[UnitMessage]:
            return sorted_unit(self._rows.messages(unit, channels))

        for t, cid, payload in merge_units(units, read):
            if (start_ns is not None and t < start_ns) or (stop_ns is not None and t >= stop_ns):
                continue
            info = channels[cid]
            yield RawMessage(info.topic, info.msgtype, t, payload, info.encoding)

    def _definitions(self, encoding: str) -> Iterator[Definition]:
        """The bag's message_definitions, file by file (ROS 2 defaults under them)."""
        for info in self._files:
            for name, (fmt, text) in info.definitions.items():
                yield Definition(name, fmt, text, f"definition of {name!r}")

    def _ros1_types(self, encoding: str) -> bool:
        return False

    def _close(self) -> None:
        self._rows.close()
        for db in self._dbs:
            db.close()
        self._dbs.clear()
        if self._tmpdir is not None:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            self._tmpdir = None


def open_sqlite_log(path: Path, meta: BagMetadata | None = None) -> SqliteLog:
    """Open a bare .db3 (meta None) or a SQLite bag folder; LogOpenError/LogReadError."""
    try:
        return SqliteLog(path, meta)
    except (LogOpenError, LogReadError):
        raise
    except sqlite3.Error as exc:
        raise LogReadError(f"{path}: bag database unreadable: {one_line(exc)}") from exc
