"""ROS 2 bags (sqlite3 or mcap storage, any metadata version) and ROS 1 bags via `rosbags`."""

from __future__ import annotations

import heapq
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import zstandard
from rosbags.rosbag1 import Reader as Rosbag1Reader
from rosbags.rosbag2 import Reader as Rosbag2Reader
from rosbags.rosbag2.storage_mcap import McapReader as Rosbag2McapStorage

from syncaudit.errors import LogOpenError, LogReadError
from syncaudit.logs.base import LogReader
from syncaudit.logs.model import LogSummary, RawMessage, TopicInfo
from syncaudit.logs.typesys import Definition, one_line

if TYPE_CHECKING:
    pass


class RosbagsLog(LogReader):
    """A ROS 1 `.bag` or a ROS 2 bag (directory, bare `.db3`, or rosbag2 `.mcap`)."""

    def __init__(self, path: Path, ros1: bool) -> None:
        self.path = path
        self.ros1 = ros1
        self.warnings = []
        reader_cls: Any = Rosbag1Reader if ros1 else Rosbag2Reader
        kind = "ROS 1 bag" if ros1 else "ROS 2 bag"
        try:
            self._reader = reader_cls(path)
            self._reader.open()
        except Exception as exc:  # rosbags: ReaderError, OSError, apsw and YAML errors
            raise LogOpenError(f"{path}: cannot open as a {kind}: {one_line(exc)}") from exc
        try:
            self.summary = self._make_summary()
        except Exception as exc:  # metadata with wrong value types
            self._reader.close()
            raise LogOpenError(f"{path}: cannot read the {kind} index: {one_line(exc)}") from exc

    def _storages(self) -> list[Any]:
        """The per-file storage readers of a bag directory (one entry for a bare file)."""
        storage = self._reader.storage if not self.ros1 else None
        return list(getattr(storage, "storages", None) or [storage])

    def _container(self) -> str:
        if self.ros1:
            return "rosbag1"
        if any(isinstance(s, Rosbag2McapStorage) for s in self._storages()):
            return "rosbag2-mcap"
        return "rosbag2-sqlite3"

    def _make_summary(self) -> LogSummary:
        count = int(self._reader.message_count)
        summary = LogSummary(
            path=str(self.path),
            container=self._container(),
            start_ns=int(self._reader.start_time) if count else None,
            end_ns=int(self._reader.end_time) - 1 if count else None,  # rosbags: last + 1
            message_count=count,
        )
        for conn in self._reader.connections:
            prior = summary.topics.get(conn.topic)
            prior_count = prior.count or 0 if prior is not None else 0
            summary.topics[conn.topic] = TopicInfo(
                name=conn.topic,
                msgtype=conn.msgtype,
                encoding=_encoding(conn, self.ros1),
                count=int(conn.msgcount) + prior_count,
                has_definition=bool(conn.msgdef.data)
                or bool(prior is not None and prior.has_definition),
            )
        return summary

    def _messages(
        self, topics: frozenset[str] | None, start_ns: int | None, stop_ns: int | None
    ) -> Iterator[RawMessage]:
        """Raw messages in log-time order; the files of a split bag are merged by time."""
        storages = self._storages()
        if len(storages) > 1:
            stream = self._merged(storages, topics, start_ns, stop_ns)
        else:
            stream = self._single(topics, start_ns, stop_ns)
        try:
            yield from stream
        except Exception as exc:  # rosbags, apsw, zstd and decompressor errors
            raise LogReadError(f"{self.path}: damaged bag data: {one_line(exc)}") from exc

    def _single(
        self, topics: frozenset[str] | None, start_ns: int | None, stop_ns: int | None
    ) -> Iterator[RawMessage]:
        conns = [c for c in self._reader.connections if topics is None or c.topic in topics]
        if not conns:  # rosbags reads every connection when given none
            return
        for conn, log_time, data in self._reader.messages(
            connections=conns, start=start_ns, stop=stop_ns
        ):
            yield RawMessage(
                conn.topic, conn.msgtype, int(log_time), data, _encoding(conn, self.ros1)
            )

    def _merged(
        self,
        storages: list[Any],
        topics: frozenset[str] | None,
        start_ns: int | None,
        stop_ns: int | None,
    ) -> Iterator[RawMessage]:
        """Merge the files of a split bag by log time.

        rosbags reads the files one after the other, which is out of order where a
        recorder wrote a message into the next file after a later-stamped one (split
        boundaries of multi-threaded recorders). Each file is time-ordered on its own.
        """
        compressed = self._reader.compression_mode == "message"

        def one(storage: Any) -> Iterator[RawMessage]:
            conns = [c for c in storage.connections if topics is None or c.topic in topics]
            if not conns:
                return
            for conn, log_time, data in storage.messages(conns, start_ns, stop_ns):
                raw = (
                    zstandard.ZstdDecompressor().decompressobj().decompress(data)
                    if compressed
                    else data
                )
                yield RawMessage(
                    conn.topic, conn.msgtype, int(log_time), raw, _encoding(conn, False)
                )

        yield from heapq.merge(*(one(s) for s in storages), key=lambda m: m.log_time_ns)

    def _definitions(self, encoding: str) -> Iterator[Definition]:
        """The bag's connection definitions."""
        for c in self._reader.connections:
            fmt = "ros2idl" if c.msgdef.format.name == "IDL" else "msg"
            yield Definition(c.msgtype, fmt, c.msgdef.data, f"definition of {c.msgtype!r}")

    def _ros1_types(self, encoding: str) -> bool:
        return self.ros1

    def _close(self) -> None:
        self._reader.close()


def _encoding(conn: Any, ros1: bool) -> str:
    """'ros1' for ROS 1 connections, else the rosbag2 serialization format ('cdr')."""
    if ros1:
        return "ros1"
    return str(getattr(conn.ext, "serialization_format", "cdr"))
