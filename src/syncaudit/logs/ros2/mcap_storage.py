"""ROS 2 bag folders with MCAP storage: one or many `.mcap` files read as one log.

Each file is an `McapLog`; messages merge across files by log time (ties: by file path,
then file order), and the chunks of every file are the read units of the
chunk-parallel path, so a bag folder is audited as fast as the bare `.mcap` it holds.
"""

from __future__ import annotations

import heapq
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from syncaudit.errors import LogOpenError
from syncaudit.logs.base import LogReader
from syncaudit.logs.mcap.reader import McapLog
from syncaudit.logs.model import ChannelInfo, LogSummary, RawMessage, ReadUnit, TopicInfo

if TYPE_CHECKING:
    from rosbags.interfaces.typing import Typesdict


def open_mcap_bag(folder: Path, files: list[Path]) -> LogReader:
    """Open a rosbag2 folder whose storage files (`files`, in metadata order) are MCAP."""
    if not files:
        raise LogOpenError(f"{folder}: ROS 2 bag lists no storage files")
    return McapBag(folder, files)


class McapBag(LogReader):
    """The MCAP files of one ROS 2 bag folder, read as one log (container 'rosbag2-mcap')."""

    def __init__(self, folder: Path, files: list[Path]) -> None:
        self.path = folder
        self.warnings = []
        self._logs: list[McapLog] = []
        try:
            for file in files:
                self._logs.append(McapLog(file))
        except BaseException:
            for log in self._logs:
                log.close()
            raise
        for log in self._logs:
            for warning in log.warnings:
                self.warn(warning.code, warning.message)
        self.summary = self._merged_summary()

    def _merged_summary(self) -> LogSummary:
        """Times, counts and topics of every file together."""
        parts = [log.summary for log in self._logs]
        starts = [p.start_ns for p in parts if p.start_ns is not None]
        ends = [p.end_ns for p in parts if p.end_ns is not None]
        counts = [p.message_count for p in parts]
        total = None if any(c is None for c in counts) else sum(c or 0 for c in counts)
        summary = LogSummary(
            str(self.path),
            "rosbag2-mcap",
            min(starts) if starts else None,
            max(ends) if ends else None,
            total,
        )
        for part in parts:
            for name, info in part.topics.items():
                prior = summary.topics.get(name)
                if prior is not None:
                    count = (
                        None
                        if prior.count is None or info.count is None
                        else prior.count + info.count
                    )
                    info = TopicInfo(
                        name,
                        prior.msgtype,
                        prior.encoding,
                        count,
                        prior.has_definition or info.has_definition,
                    )
                summary.topics[name] = info
        return summary

    def _messages(
        self, topics: frozenset[str] | None, start_ns: int | None, stop_ns: int | None
    ) -> Iterator[RawMessage]:
        """Every file's messages merged by log time (ties: by file path, as the parallel
        path and the other bag readers order them)."""
        ordered = sorted(self._logs, key=lambda log: str(log.path))
        streams = [log.messages(topics, start_ns, stop_ns) for log in ordered]
        yield from heapq.merge(*streams, key=lambda m: m.log_time_ns)
        for log in self._logs:  # warnings found while reading (e.g. undeclared channels)
            for warning in log.warnings:
                self.warn(warning.code, warning.message)

    def read_units(self, topics: frozenset[str]) -> list[ReadUnit] | None:
        """The chunks of every file; None where some file has no index, or where the files
        number their channels differently (their ids then cannot share one table)."""
        if self._channel_table(topics) is None:
            return None
        units: list[ReadUnit] = []
        for log in self._logs:
            part = log.read_units(topics)
            if part is None:
                return None
            units.extend(part)
        return units

    def unit_channels(self, topics: frozenset[str]) -> dict[int, ChannelInfo]:
        """Channel id -> topic, type, encoding, the same in every file."""
        return self._channel_table(topics) or {}

    def _channel_table(self, topics: frozenset[str]) -> dict[int, ChannelInfo] | None:
        table: dict[int, ChannelInfo] = {}
        for log in self._logs:
            for cid, info in log.unit_channels(topics).items():
                if table.setdefault(cid, info) != info:
                    return None
        # An id wanted in one file must not mean an unwanted topic in another.
        for log in self._logs:
            for cid, info in log.unit_channels(frozenset(log.topics)).items():
                if cid in table and table[cid] != info:
                    return None
        return table

    def log_types(self, encoding: str) -> Typesdict:
        """Every file's types of `encoding`, the first file's winning (each file's warnings
        are the bag's)."""
        types: Typesdict = {}
        for log in self._logs:
            for name, definition in log.log_types(encoding).items():
                types.setdefault(name, definition)
            for warning in log.warnings:
                self.warn(warning.code, warning.message)
        return types

    def _close(self) -> None:
        for log in self._logs:
            log.close()
