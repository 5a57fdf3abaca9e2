"""Per-worker readers of `ReadUnit`s, one class per unit kind, found through a registry.

A log that can be split for parallel reading says so with `LogReader.read_units()`; each
worker then reads its units with the reader class registered for their kind. Adding a
kind is one line in `UNIT_READERS` ("module:Class", imported only when a unit of that kind
is read, so a bare MCAP audit never imports a bag library).

A reader class is constructed as `cls(source, check_crc=...)` (or `cls(source)` when it
takes no `check_crc`; one per worker and file)
and offers `messages(unit, channels)` yielding (log time ns, index in unit, channel id,
payload) in file order (payloads may be views valid until the next unit is read) and
`close()`. Damage raises LogReadError naming the file and the unit's offset.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Iterator
from typing import Protocol

from syncaudit.logs.model import ChannelInfo, ReadUnit

UNIT_READERS: dict[str, str] = {
    "mcap-chunk": "syncaudit.logs.mcap.chunk_reader:McapChunkUnitReader",
    "mcap-cut-chunk": "syncaudit.logs.mcap.reader:McapCutChunkUnitReader",
    "mcap-remote-chunks": "syncaudit.logs.mcap.remote:RemoteChunksUnitReader",
    "rosbag1-chunk": "syncaudit.logs.ros1.format:Rosbag1ChunkReader",
    "rosbag1-remote-chunk": "syncaudit.logs.ros1.remote:RemoteRosbag1ChunkReader",
    "sqlite-rows": "syncaudit.logs.ros2.sqlite_rows:SqliteRowsReader",
    "pcap-range": "syncaudit.logs.pcap.reader:PcapRangeReader",
}
"""Unit kind -> "module:Class" of its per-worker reader."""


class UnitReader(Protocol):
    """Reads units of one kind from one file, in a worker process (or the parent)."""

    def messages(
        self, unit: ReadUnit, channels: dict[int, ChannelInfo]
    ) -> Iterator[tuple[int, int, int, bytes | memoryview]]:
        """(log time ns, index in unit, channel id, payload) of the unit's wanted messages."""
        ...

    def close(self) -> None:
        """Release the file."""
        ...


def open_unit_reader(kind: str, source: str, *, check_crc: bool = False) -> UnitReader:
    """A reader for units of `kind` in file `source`."""
    try:
        target = UNIT_READERS[kind]
    except KeyError:
        raise ValueError(f"no reader registered for read units of kind {kind!r}") from None
    module, _, name = target.partition(":")
    cls = getattr(importlib.import_module(module), name)
    if "check_crc" in inspect.signature(cls).parameters:
        reader: UnitReader = cls(source, check_crc=check_crc)
    else:  # a container without checksums to verify
        reader = cls(source)
    return reader


def group_units(units: list[ReadUnit], target_bytes: int) -> list[list[ReadUnit]]:
    """Consecutive units (in time order) grouped to about `target_bytes` of cost each."""
    groups: list[list[ReadUnit]] = []
    current: list[ReadUnit] = []
    size = 0
    for unit in sorted(units, key=lambda u: (u.start_ns, u.source, u.offset)):
        current.append(unit)
        size += unit.cost
        if size >= target_bytes:
            groups.append(current)
            current, size = [], 0
    if current:
        groups.append(current)
    return groups
