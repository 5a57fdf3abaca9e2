"""The interface every log backend implements: a summary, streamed raw messages, warnings."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterable, Iterator
from types import TracebackType
from typing import TYPE_CHECKING

from syncaudit.logs.model import (
    ChannelInfo,
    LogSummary,
    LogWarning,
    RawMessage,
    ReadUnit,
    TopicInfo,
)
from syncaudit.logs.typesys import Definition, TypeRegistry, log_types

if TYPE_CHECKING:
    from rosbags.interfaces.typing import Typesdict

    from syncaudit.remote.ranges import FetchStats


class LogReader(ABC):
    """An open log. Use as a context manager; messages stream in log-time order."""

    summary: LogSummary
    warnings: list[LogWarning]
    closed: bool = False

    @property
    def topics(self) -> dict[str, TopicInfo]:
        """Topics of the log by name."""
        return self.summary.topics

    def messages(
        self,
        topics: Iterable[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[RawMessage]:
        """Yield raw messages of `topics` (all if None) with start_ns <= log time < stop_ns.

        A single topic may be passed as a plain string. The generator reads the log as it
        is consumed; damaged data raises LogReadError when it is reached.
        """
        if self.closed:
            raise ValueError(f"{self.summary.path}: log is closed")
        wanted = (
            None if topics is None else frozenset([topics] if isinstance(topics, str) else topics)
        )
        if wanted is not None and not wanted:
            return iter(())
        if start_ns is not None and stop_ns is not None and start_ns >= stop_ns:
            return iter(())
        return self._messages(wanted, start_ns, stop_ns)

    @abstractmethod
    def _messages(
        self, topics: frozenset[str] | None, start_ns: int | None, stop_ns: int | None
    ) -> Iterator[RawMessage]:
        """Backend part of `messages`, with the selection already normalised."""

    @property
    def fetch_stats(self) -> FetchStats | None:
        """For a log read from a URL: what reading it has fetched so far, by this process
        and its workers, against its size and needed chunks (None for a local file)."""
        return None

    def read_units(self, topics: frozenset[str]) -> list[ReadUnit] | None:
        """Pieces of the log holding `topics` that workers can read on their own.

        None (the default): the log cannot be split; read it serially with `messages()`.
        """
        return None

    def unit_channels(self, topics: frozenset[str]) -> dict[int, ChannelInfo]:
        """Channel/connection id -> topic, type, encoding for the units' wanted messages."""
        return {}

    def type_registry(self, encoding: str) -> TypeRegistry:
        """Types for messages of the given encoding ('cdr' or 'ros1') in this log: its own
        definitions, then schemas/, then ROS defaults (built once per encoding)."""
        registries: dict[str, TypeRegistry] = self.__dict__.setdefault("_registries", {})
        if encoding not in registries:
            registries[encoding] = TypeRegistry(
                ros1=self._ros1_types(encoding), log_types=self.log_types(encoding)
            )
        return registries[encoding]

    def log_types(self, encoding: str) -> Typesdict:
        """The types the log's own definitions give for messages of `encoding` (a definition
        that cannot be parsed is a 'bad-schema' warning)."""
        return log_types(self._definitions(encoding), self.warn)

    def _definitions(self, encoding: str) -> Iterable[Definition]:
        """The message definitions the log carries for messages of `encoding`."""
        return ()

    def _ros1_types(self, encoding: str) -> bool:
        """Whether the ROS defaults under the log's definitions are ROS 1's (else ROS 2's)."""
        return encoding == "ros1"

    def deserialize(self, msg: RawMessage) -> object:
        """Deserialize one raw message with the log's own definitions (or schemas/).

        Raises UnknownTypeError where no definition is known, LogReadError where the bytes
        do not fit it.
        """
        registry = self.type_registry(msg.encoding)
        for problem in registry.problems:
            self.warn("bad-project-schema", problem)
        return registry.deserialize(msg.data, msg.msgtype, msg.encoding)

    def warn(self, code: str, message: str) -> None:
        """Record a warning once."""
        warning = LogWarning(code, message)
        if warning not in self.warnings:
            self.warnings.append(warning)

    def close(self) -> None:
        """Release the file handles; safe to call twice."""
        if not self.closed:
            self.closed = True
            self._close()

    @abstractmethod
    def _close(self) -> None:
        """Backend part of `close`."""

    def __enter__(self) -> LogReader:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
