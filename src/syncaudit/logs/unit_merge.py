"""Serial reading of a log's units in log-time order: units opened as the time reaches them."""

from __future__ import annotations

import heapq
from collections.abc import Callable, Iterator

from syncaudit.logs.model import ReadUnit

UnitMessage = tuple[int, int, int, bytes | memoryview]
"""(log_time_ns, index_in_unit, channel id, payload) as a per-worker reader yields them."""


def sorted_unit(messages: Iterator[UnitMessage]) -> Iterator[UnitMessage]:
    """A unit's messages in (log time, index) order (recorders write in arrival order)."""
    return iter(sorted(messages, key=_time_index))


def _time_index(item: UnitMessage) -> tuple[int, int]:
    return item[0], item[1]


def merge_units(
    units: list[ReadUnit], read: Callable[[ReadUnit], Iterator[UnitMessage]]
) -> Iterator[tuple[int, int, bytes | memoryview]]:
    """(log_time_ns, channel id, payload) of all units in (log time, unit offset, index) order.

    `read` gives one unit's messages in (log time, index) order. A unit is read only once
    the merge reaches its start time, so memory holds the units overlapping in time, not
    the log.
    """
    pending = sorted(units, key=lambda u: (u.start_ns, u.source, u.offset))
    heap: list[tuple[int, str, int, int, int, bytes | memoryview, Iterator[UnitMessage]]] = []
    taken = 0
    while heap or taken < len(pending):
        while taken < len(pending) and (not heap or pending[taken].start_ns <= heap[0][0]):
            unit = pending[taken]
            taken += 1
            stream = read(unit)
            for t, index, cid, payload in stream:
                heapq.heappush(heap, (t, unit.source, unit.offset, index, cid, payload, stream))
                break
        if not heap:
            break
        t, source, offset, _index, cid, payload, stream = heapq.heappop(heap)
        for t2, index, cid2, payload2 in stream:
            heapq.heappush(heap, (t2, source, offset, index, cid2, payload2, stream))
            break
        yield t, cid, payload
