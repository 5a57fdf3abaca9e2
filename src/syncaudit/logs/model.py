"""Plain records every log backend yields: raw messages, topics, warnings, a summary."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True, slots=True)
class RawMessage:
    """One serialized message as stored in the log; `data` is never deserialized here."""

    topic: str
    msgtype: str
    """ROS 2 style type name, e.g. 'velodyne_msgs/msg/VelodyneScan'."""
    log_time_ns: int
    data: bytes | memoryview
    encoding: str
    """'cdr' (ROS 2) or 'ros1'."""


@dataclass(frozen=True, slots=True)
class TopicInfo:
    """A topic of a log: its type, serialization, and how many messages it holds."""

    name: str
    msgtype: str
    encoding: str
    count: int | None
    """Messages on the topic; None where the container has no index to tell."""
    has_definition: bool
    """True where the log itself carries the message definition."""


@dataclass(frozen=True, slots=True)
class LogWarning:
    """Something the reader noticed that limits what can be trusted, with a short code."""

    code: str
    message: str


@dataclass(slots=True)
class LogSummary:
    """What a log's index says about it, before reading any message."""

    path: str
    container: str
    """'mcap', 'rosbag2-sqlite3', 'rosbag2-mcap' or 'rosbag1'."""
    start_ns: int | None
    end_ns: int | None
    message_count: int | None
    topics: dict[str, TopicInfo] = field(default_factory=dict)

    @property
    def duration_s(self) -> float | None:
        """Duration from first to last message in seconds."""
        if self.start_ns is None or self.end_ns is None:
            return None
        return (self.end_ns - self.start_ns) / 1e9


@dataclass(frozen=True, slots=True)
class ReadUnit:
    """A piece of a log one worker reads on its own (an MCAP or ROS 1 chunk, SQLite rows)."""

    source: str
    """Path of the file holding it."""
    kind: str
    """'mcap-chunk' | 'rosbag1-chunk' | 'sqlite-rows' (a key of `logs.units.UNIT_READERS`)."""
    offset: int
    """Byte offset of the chunk record; first rowid for sqlite-rows."""
    length: int
    """Bytes of the chunk record; rowid past the last for sqlite-rows."""
    start_ns: int
    """First log time in the unit."""
    end_ns: int
    """Last log time in the unit."""
    cost: int
    """Bytes to read, for grouping units into tasks."""


@dataclass(frozen=True, slots=True)
class ChannelInfo:
    """What a worker needs to know of a channel/connection id: picklable, no schema text."""

    topic: str
    msgtype: str
    """ROS 2 style type name."""
    encoding: str
    """'cdr' or 'ros1'."""
    prefix_bytes: int = 0
    """0: the whole payload is wanted. N > 0: its reader only looks at the first N bytes
    (an image's header), so a unit reader may hand over just those where that saves
    reading the rest (SQLite blobs); others give the whole payload."""
