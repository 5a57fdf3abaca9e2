"""The interface every log backend implements: a summary, streamed raw messages, warnings."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterable, Iterator
from types import TracebackType

from syncaudit.logs.model import LogSummary, LogWarning, RawMessage, TopicInfo
from syncaudit.logs.typesys import TypeRegistry


class LogReader(ABC):
    """An open log. Use as a context manager; messages stream in log-time order."""

    summary: LogSummary
    warnings: list[LogWarning]

    @property
    def topics(self) -> dict[str, TopicInfo]:
        """Topics of the log by name."""
        return self.summary.topics

    @abstractmethod
    def messages(
        self,
        topics: Iterable[str] | None = None,
        start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[RawMessage]:
        """Yield raw messages of `topics` (all if None) with start_ns <= log time < stop_ns."""

    @abstractmethod
    def type_registry(self, encoding: str) -> TypeRegistry:
        """Types for messages of the given encoding ('cdr' or 'ros1') in this log."""

    def deserialize(self, msg: RawMessage) -> object:
        """Deserialize one raw message with the log's own definitions (or schemas/)."""
        return self.type_registry(msg.encoding).deserialize(msg.data, msg.msgtype, msg.encoding)

    def warn(self, code: str, message: str) -> None:
        """Record a warning once."""
        warning = LogWarning(code, message)
        if warning not in self.warnings:
            self.warnings.append(warning)

    @abstractmethod
    def close(self) -> None:
        """Release the file handles."""

    def __enter__(self) -> LogReader:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def selected(topics: Iterable[str] | None) -> frozenset[str] | None:
    """Normalise a topic selection to a frozenset (None = all)."""
    return None if topics is None else frozenset(topics)
