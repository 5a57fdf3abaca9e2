"""One pass over chosen topics of a log, each message made into a small item, in log order.

What a message becomes is the caller's `Extractor` (decoding LiDAR packets, reading an
image header, deserialising an exposure record): pure, and picklable, so for a log that
offers read units (`LogReader.read_units`: MCAP chunks, ROS 1 chunks, SQLite row ranges)
it runs in worker processes, one group of units each, on all cores, each unit read by the
reader class registered for its kind (`logs.unit_readers`); the parent merges the groups
back into log-time order (ties broken by file, unit offset and index in the unit), so the
serial and parallel paths yield the same items in the same order. A log of one group is
read in the parent: a pool would only cost.
"""

from __future__ import annotations

import contextlib
import gc
import heapq
import itertools
import multiprocessing
import os
from collections.abc import Callable, Iterator
from concurrent.futures import Future
from dataclasses import dataclass, field, replace
from typing import Any, Generic, Protocol, TypeVar

from syncaudit.logs.base import LogReader
from syncaudit.logs.model import ChannelInfo, RawMessage, ReadUnit
from syncaudit.logs.unit_readers import UnitReader, group_units, open_unit_reader
from syncaudit.workers import return_large_frees, worker_pool

GROUP_BYTES = 8 * 1024 * 1024
"""Compressed bytes of log per worker task: large enough to amortise, small for memory
(a group's result waits in the parent until merged: on a 128-beam log 8 MB of chunks
make ~10 MB of LiDAR samples; with 24 MB the parent's peak RSS on a dense 10-minute log
was 165 MB, with 8 MB 106 MB, in the same time)."""
TASKS_PER_WORKER = 2
"""Tasks in flight per worker: enough queued work that workers never wait on a parent
busy with something else (its one-off imports); results are small, so memory stays low."""

ItemT = TypeVar("ItemT")
ItemT_co = TypeVar("ItemT_co", covariant=True)


class Extractor(Protocol[ItemT_co]):
    """What a read makes of each message of its topics; pure and picklable, since worker
    processes run it (forked ones get it by token, spawned ones by pickle)."""

    @property
    def topics(self) -> list[str]:
        """Every topic to read."""
        ...

    def prefix_bytes(self, topic: str) -> int:
        """Bytes of a message on `topic` the extraction looks at (0: all); readers that can
        skip the rest (image pixels) do."""
        ...

    def rosbags_encodings(self, log: LogReader) -> set[str]:
        """Encodings of messages the extraction deserialises through the log's type
        registry: built once before forking (~80 ms of schema parsing), only where needed."""
        ...

    def extract(self, msg: RawMessage, log: LogReader) -> ItemT_co | None:
        """The item one message contributes (None for nothing)."""
        ...


@dataclass(frozen=True, slots=True)
class WholeMessages:
    """The part of an extractor that reads one topic's messages whole, from their bytes
    (no type registry): a LiDAR's packets or clouds. Subclasses add `extract`."""

    topic: str

    @property
    def topics(self) -> list[str]:
        """The one topic."""
        return [self.topic]

    def prefix_bytes(self, topic: str) -> int:
        """Messages are read whole."""
        return 0

    def rosbags_encodings(self, log: LogReader) -> set[str]:
        """None: the messages are decoded from their bytes."""
        return set()


def default_jobs() -> int:
    """Worker processes to use: the cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def iter_items(
    log: LogReader,
    extractor: Extractor[ItemT],
    jobs: int = 1,
    *,
    check_crc: bool = False,
    meanwhile: Callable[[], object] | None = None,
) -> Iterator[ItemT]:
    """Every item of the extractor's topics, in log-time order; parallel where the log allows.

    `check_crc` verifies each MCAP chunk's CRC (about as much CPU as decompressing it).
    `meanwhile` is work of the caller's (e.g. imports it needs afterwards) run once: in
    the parallel path as soon as the workers have their first tasks, so it overlaps them;
    otherwise before the read.
    """
    with _collection_paused():
        yield from _items(log, extractor, jobs, check_crc, meanwhile)


@contextlib.contextmanager
def _collection_paused() -> Iterator[None]:
    """No cyclic garbage collection while a log is read: the items and rows made then hold
    no reference cycles (reference counting frees them), and the collector's passes over
    them cost ~5 % of the parent's CPU (12 of 250 ms per 2 GB audit). Worker processes,
    forked meanwhile, read with the collector paused too."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            _keep_out_of_young_passes()
            gc.enable()


def _keep_out_of_young_passes() -> None:
    """Move what the read made (rows the analysis keeps) out of the collector's young
    generations, which would otherwise all be walked by the first pass once it runs again
    (~4 ms per 2 GB audit): into the oldest generation (freeze, then thaw), or, where the
    caller keeps a frozen heap (the CLI freezes its imports), into that heap. An audit
    makes no cyclic garbage (gc.collect() after one finds nothing), so this keeps nothing
    alive that the collector would have freed."""
    owned = gc.get_freeze_count() == 0
    gc.freeze()
    if owned:
        gc.unfreeze()


def _items(
    log: LogReader,
    extractor: Extractor[ItemT],
    jobs: int,
    check_crc: bool,
    meanwhile: Callable[[], object] | None,
) -> Iterator[ItemT]:
    """`iter_items`' body."""
    topics = frozenset(extractor.topics)
    units = log.read_units(topics)
    groups = group_units(units, GROUP_BYTES) if units is not None else []
    if meanwhile is not None and not (jobs > 1 and len(groups) > 1):
        meanwhile()
    if units is None:
        extract = extractor.extract
        for msg in log.messages(extractor.topics):
            item = extract(msg, log)
            if item is not None:
                yield item
        return
    channels = _with_prefixes(log.unit_channels(topics), extractor)
    ranks = _source_ranks(units)
    if jobs > 1 and len(groups) > 1:
        results = _parallel_results(log, groups, channels, extractor, jobs, check_crc, meanwhile)
        yield from _merged(groups, results)
        return
    readers = _Readers(check_crc)
    try:
        serial = (_extract_units(log, readers, g, channels, ranks, extractor) for g in groups)
        yield from _merged(groups, serial)
    finally:
        readers.close()


def _with_prefixes(
    channels: dict[int, ChannelInfo], extractor: Extractor[object]
) -> dict[int, ChannelInfo]:
    """The channels, those the extractor reads the start of marked as read for it only."""
    out = {}
    for cid, info in channels.items():
        prefix = extractor.prefix_bytes(info.topic)
        out[cid] = replace(info, prefix_bytes=prefix) if prefix > 0 else info
    return out


def _source_ranks(units: list[ReadUnit]) -> dict[str, int]:
    """Files of a log by path (ties in time across files: as the readers' serial merges)."""
    return {source: rank for rank, source in enumerate(sorted({u.source for u in units}))}


# ---- worker side -------------------------------------------------------------------------

Keyed = tuple[int, int, int, int, ItemT]
"""(log time, file rank (by path), unit offset, index in unit, item): the merge order."""


class _Readers:
    """One unit reader per (kind, file), opened on first use and reused for every task."""

    def __init__(self, check_crc: bool) -> None:
        self.check_crc = check_crc
        self._open: dict[tuple[str, str], UnitReader] = {}

    def get(self, unit: ReadUnit) -> UnitReader:
        """The reader of `unit`'s kind and file."""
        key = (unit.kind, unit.source)
        reader = self._open.get(key)
        if reader is None:
            reader = open_unit_reader(unit.kind, unit.source, check_crc=self.check_crc)
            self._open[key] = reader
        return reader

    def close(self) -> None:
        """Close every reader."""
        for reader in self._open.values():
            reader.close()
        self._open.clear()


_INHERITED_LOGS: dict[str, LogReader] = {}
"""Logs open in the parent while its pool runs: forked workers use them as they are."""
_WORKER_STATE: dict[tuple[str, bool], tuple[LogReader, _Readers]] = {}
"""Per worker process: the log and its unit readers (buffers reused for every task)."""
_INHERITED_TASKS: dict[str, _Task[Any]] = {}
"""Task of each pool running in the parent, by token: forked workers look theirs up rather
than unpickling it (its channels and extractor, ~3 KB) with every group."""
_task_tokens = itertools.count()


@dataclass(frozen=True, slots=True)
class _Task(Generic[ItemT]):
    """What a worker needs besides the units: picklable."""

    log_path: str
    channels: dict[int, ChannelInfo]
    ranks: dict[str, int]
    extractor: Extractor[ItemT]
    check_crc: bool = False
    open_as: str = field(default="", repr=False)
    """What a spawned worker opens instead of `log_path`: a remote log's URL as given (a
    signed URL's query string, which `log_path` and every message leave out). Not shown."""


def _extract_group(task: _Task[ItemT] | str, units: list[ReadUnit]) -> list[Keyed[ItemT]]:
    """Read and extract one group of units (the worker task); `task` is the task itself, or
    a forked worker's token of it in `_INHERITED_TASKS`."""
    if isinstance(task, str):
        task = _INHERITED_TASKS[task]
    key = (task.log_path, task.check_crc)
    if key not in _WORKER_STATE:
        log = _INHERITED_LOGS.get(task.log_path)
        if log is None:  # spawned, not forked: open the log afresh
            from syncaudit.logs.open import open_log

            log = open_log(task.open_as or task.log_path)
        _WORKER_STATE[key] = (log, _Readers(task.check_crc))
    log, readers = _WORKER_STATE[key]
    return _extract_units(log, readers, units, task.channels, task.ranks, task.extractor)


def _extract_units(
    log: LogReader,
    readers: _Readers,
    units: list[ReadUnit],
    channels: dict[int, ChannelInfo],
    ranks: dict[str, int],
    extractor: Extractor[ItemT],
) -> list[Keyed[ItemT]]:
    """The items of a group of units, sorted into merge order."""
    out: list[Keyed[ItemT]] = []
    extract = extractor.extract
    for unit in units:
        rank = ranks[unit.source]
        for log_time, index, cid, data in readers.get(unit).messages(unit, channels):
            info = channels[cid]
            msg = RawMessage(info.topic, info.msgtype, log_time, data, info.encoding)
            item = extract(msg, log)
            if item is not None:
                out.append((log_time, rank, unit.offset, index, item))
    out.sort(key=_merge_key)
    return out


def _merge_key(keyed: Keyed[object]) -> tuple[int, int, int, int]:
    return keyed[0], keyed[1], keyed[2], keyed[3]


def _parallel_results(
    log: LogReader,
    groups: list[list[ReadUnit]],
    channels: dict[int, ChannelInfo],
    extractor: Extractor[ItemT],
    jobs: int,
    check_crc: bool,
    meanwhile: Callable[[], object] | None = None,
) -> Iterator[list[Keyed[ItemT]]]:
    """Each group's extracted items, in group order, computed by `jobs` worker processes;
    `meanwhile` runs here once the first tasks are submitted."""
    path = log.summary.path
    ranks = _source_ranks([u for g in groups for u in g])
    task = _Task(path, channels, ranks, extractor, check_crc, open_as=getattr(log, "url", ""))
    methods = multiprocessing.get_all_start_methods()
    context = multiprocessing.get_context("fork" if "fork" in methods else "spawn")
    sent: _Task[ItemT] | str = task
    if context.get_start_method() == "fork":
        # Forked workers inherit the open log, with the type registries they will need
        # built once here (parsing a log's schemas costs ~80 ms: only where needed), and
        # the task: each group is sent with its token.
        for encoding in extractor.rosbags_encodings(log):
            log.type_registry(encoding)
        _INHERITED_LOGS[path] = log
        sent = f"{path}#{next(_task_tokens)}"
        _INHERITED_TASKS[sent] = task
    # Forked workers share the parent's heap copy-on-write; a frozen heap is never
    # traversed (or written) by their garbage collector, which would copy it page by page.
    # (A caller's own freeze is left as it is.)
    freeze = gc.get_freeze_count() == 0
    if freeze:
        gc.freeze()
    return_large_frees()
    try:
        with worker_pool(jobs, context, label=f"{path}: a reader worker process") as pool:
            window: list[Future[list[Keyed[ItemT]]]] = []
            submitted = 0
            for _ in range(len(groups)):
                while submitted < len(groups) and len(window) < TASKS_PER_WORKER * jobs:
                    window.append(pool.submit(_extract_group, sent, groups[submitted]))
                    submitted += 1
                if meanwhile is not None:
                    meanwhile()
                    meanwhile = None
                yield window.pop(0).result()
    finally:
        if freeze:
            gc.unfreeze()
        _INHERITED_LOGS.pop(path, None)
        if isinstance(sent, str):
            _INHERITED_TASKS.pop(sent, None)


def _merged(groups: list[list[ReadUnit]], results: Iterator[list[Keyed[ItemT]]]) -> Iterator[ItemT]:
    """Group results merged into one log-time order (units of a log may overlap in time)."""
    pending: list[Keyed[ItemT]] = []
    for done, result in enumerate(results):
        # Everything before the next group's first message can no longer be overtaken.
        horizon = min(u.start_ns for u in groups[done + 1]) if done + 1 < len(groups) else None
        merged = list(heapq.merge(pending, result, key=_merge_key))
        if horizon is None:
            ready, pending = merged, []
        else:
            cut = next((i for i, k in enumerate(merged) if k[0] >= horizon), len(merged))
            ready, pending = merged[:cut], merged[cut:]
        for keyed in ready:
            yield keyed[4]


__all__ = ["GROUP_BYTES", "Extractor", "default_jobs", "iter_items"]
