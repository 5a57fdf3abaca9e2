"""Two logs read as one: a bag holding the cameras and a capture of the LiDAR traffic
recorded beside it on the same host (`audit LOG --lidar-capture CAPTURE`).

The capture's time stamps are the host's receive times, the bag's log times the same host's
clock, so the two merge on log time as they are. Topics are the union (a name in both is
refused); read units are both logs' own, the capture's channel ids moved past the bag's, so
each unit is read by its own kind's reader in the workers.
"""

from __future__ import annotations

import heapq
from collections.abc import Iterator

from syncaudit.errors import LogOpenError
from syncaudit.logs.base import LogReader
from syncaudit.logs.model import ChannelInfo, LogSummary, RawMessage, ReadUnit

CHANNEL_SHIFT = 1 << 40
"""Added to the second log's channel ids: no container has that many channels."""


def _earliest(a: int | None, b: int | None) -> int | None:
    return b if a is None else a if b is None else min(a, b)


def _latest(a: int | None, b: int | None) -> int | None:
    return b if a is None else a if b is None else max(a, b)


class CombinedLog(LogReader):
    """`main` (cameras) and `lidar` (a capture) as one log; closes both."""

    def __init__(self, main: LogReader, lidar: LogReader) -> None:
        self.main, self.lidar = main, lidar
        clash = sorted(set(main.topics) & set(lidar.topics))
        if clash:
            raise LogOpenError(f"{lidar.summary.path}: topic {clash[0]} is also in the log")
        self.warnings = main.warnings
        for warning in lidar.warnings:
            self.warn(warning.code, f"{lidar.summary.path}: {warning.message}")
        counts = (main.summary.message_count, lidar.summary.message_count)
        self.summary = LogSummary(
            path=main.summary.path,
            container=f"{main.summary.container}+{lidar.summary.container}",
            start_ns=_earliest(main.summary.start_ns, lidar.summary.start_ns),
            end_ns=_latest(main.summary.end_ns, lidar.summary.end_ns),
            message_count=None if None in counts else sum(c or 0 for c in counts),
            topics={**main.topics, **lidar.topics},
        )

    def deserialize(self, msg: RawMessage) -> object:
        """With the definitions of the log the topic comes from."""
        source = self.lidar if msg.topic in self.lidar.topics else self.main
        return source.deserialize(msg)

    def _messages(
        self, topics: frozenset[str] | None, start_ns: int | None, stop_ns: int | None
    ) -> Iterator[RawMessage]:
        parts = []
        for log in (self.main, self.lidar):
            wanted = set(log.topics) if topics is None else topics & set(log.topics)
            if wanted:
                parts.append(log.messages(wanted, start_ns, stop_ns))
        yield from heapq.merge(*parts, key=lambda m: m.log_time_ns)

    def read_units(self, topics: frozenset[str]) -> list[ReadUnit] | None:
        """Both logs' units, where both can be split; else None (read serially)."""
        first = self.main.read_units(topics & set(self.main.topics))
        second = self.lidar.read_units(topics & set(self.lidar.topics))
        if first is None or second is None:
            return None
        return first + second

    def unit_channels(self, topics: frozenset[str]) -> dict[int, ChannelInfo]:
        """The main log's channels, and the capture's moved past them."""
        channels = dict(self.main.unit_channels(topics & set(self.main.topics)))
        for cid, info in self.lidar.unit_channels(topics & set(self.lidar.topics)).items():
            channels[cid + CHANNEL_SHIFT] = info
        return channels

    def _close(self) -> None:
        try:
            self.main.close()
        finally:
            self.lidar.close()
