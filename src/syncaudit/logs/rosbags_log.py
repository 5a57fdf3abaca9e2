"""ROS 2 bags (sqlite3 or mcap storage, any metadata version) and ROS 1 bags via `rosbags`."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from rosbags.rosbag1 import Reader as Rosbag1Reader
from rosbags.rosbag1 import ReaderError as Rosbag1ReaderError
from rosbags.rosbag2 import Reader as Rosbag2Reader
from rosbags.rosbag2 import ReaderError as Rosbag2ReaderError

from syncaudit.errors import LogOpenError, LogReadError
from syncaudit.logs.base import LogReader, selected
from syncaudit.logs.model import LogSummary, RawMessage, TopicInfo
from syncaudit.logs.typesys import TypeRegistry, parse_definition

_ROSBAGS_ERRORS = (Rosbag1ReaderError, Rosbag2ReaderError, OSError, ValueError, KeyError)


class RosbagsLog(LogReader):
    """A ROS 1 `.bag` or a ROS 2 bag (directory, bare `.db3`, or rosbag2 `.mcap`)."""

    def __init__(self, path: Path, ros1: bool) -> None:
        self.path = path
        self.ros1 = ros1
        self.warnings = []
        reader_cls: Any = Rosbag1Reader if ros1 else Rosbag2Reader
        try:
            self._reader = reader_cls(path)
            self._reader.open()
        except _ROSBAGS_ERRORS as exc:
            kind = "ROS 1 bag" if ros1 else "ROS 2 bag"
            raise LogOpenError(f"{path}: cannot open as a {kind}: {_one_line(exc)}") from exc
        self._registry: TypeRegistry | None = None
        self.summary = self._make_summary()

    def _container(self) -> str:
        if self.ros1:
            return "rosbag1"
        if self.path.is_file():
            is_mcap = self.path.suffix == ".mcap"
        else:
            is_mcap = any(self.path.glob("*.mcap"))
        return "rosbag2-mcap" if is_mcap else "rosbag2-sqlite3"

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
            summary.topics[conn.topic] = TopicInfo(
                name=conn.topic,
                msgtype=conn.msgtype,
                encoding="ros1" if self.ros1 else _ros2_encoding(conn),
                count=int(conn.msgcount) + (prior.count or 0 if prior else 0),
                has_definition=bool(conn.msgdef.data),
            )
        return summary

    def messages(
        self,
        topics: Iterable[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[RawMessage]:
        """Raw messages in log-time order."""
        wanted = selected(topics)
        conns = [c for c in self._reader.connections if wanted is None or c.topic in wanted]
        if not conns:
            return
        encoding = {c.id: ("ros1" if self.ros1 else _ros2_encoding(c)) for c in conns}
        try:
            for conn, log_time, data in self._reader.messages(
                connections=conns, start=start_ns, stop=stop_ns
            ):
                yield RawMessage(conn.topic, conn.msgtype, int(log_time), data, encoding[conn.id])
        except _ROSBAGS_ERRORS as exc:
            raise LogReadError(f"{self.path.name}: damaged bag data: {_one_line(exc)}") from exc

    def type_registry(self, encoding: str) -> TypeRegistry:
        """Types from the bag's connection definitions, then schemas/ and ROS defaults."""
        if self._registry is None:
            log_types: dict[str, object] = {}
            for conn in self._reader.connections:
                if not conn.msgdef.data or conn.msgtype in log_types:
                    continue
                fmt = "ros2idl" if conn.msgdef.format.name == "IDL" else "msg"
                try:
                    parsed = parse_definition(fmt, conn.msgdef.data, conn.msgtype)
                except Exception as exc:  # noqa: BLE001 - a bad definition must not stop the audit
                    self.warn("bad-schema", f"definition of {conn.msgtype!r} unreadable: {exc}")
                    continue
                log_types.update({k: v for k, v in parsed.items() if k not in log_types})
            self._registry = TypeRegistry(ros1=self.ros1, log_types=log_types)
        return self._registry

    def close(self) -> None:
        """Close the bag."""
        self._reader.close()


def _ros2_encoding(conn: Any) -> str:
    fmt = getattr(conn.ext, "serialization_format", "cdr")
    return "cdr" if fmt == "cdr" else str(fmt)


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__
