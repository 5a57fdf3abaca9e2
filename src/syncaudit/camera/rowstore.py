"""One camera topic's rows as they stream in: readable rows packed into typed columns every
`PACK_ROWS`, damaged ones kept apart for the warning that counts them.

A row as a Python tuple of ints and strings costs about ten times its column values (the
image, exposure and trigger rows of one frame: ~1 KB), so holding every row of a long log
until the end grew the parent by ~4 MB a GB; packed as they come, it holds at most
`PACK_ROWS` tuples per topic.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from syncaudit.columns.table import Table

PACK_ROWS = 1024
"""Readable rows kept as tuples before they are packed into a table."""


@dataclass(frozen=True, slots=True)
class DamagedRow:
    """A camera message that could not be read: skipped, counted and reported."""

    topic: str
    log_time_ns: int
    reason: str


Row = tuple[Any, ...]
Packer = Callable[[list[Row]], "Table"]
"""Rows of one kind to their typed table (the same function for a part or for all)."""


class RowStore:
    """The rows of one kind (image, exposure, trigger) for one camera, in arrival order."""

    __slots__ = ("_pack", "_pending", "_tables", "damaged", "readable")

    def __init__(self, pack: Packer) -> None:
        self._pack = pack
        self._pending: list[Row] = []
        self._tables: list[Table] = []
        self.damaged: list[DamagedRow] = []
        """Damaged messages, in arrival order."""
        self.readable = 0
        """Readable rows appended."""

    def append(self, row: Row | DamagedRow) -> None:
        """One row (or a damaged message) more."""
        if isinstance(row, DamagedRow):
            self.damaged.append(row)
            return
        self._pending.append(row)
        self.readable += 1
        if len(self._pending) >= PACK_ROWS:
            self._tables.append(self._pack(self._pending))
            self._pending = []

    def extend(self, rows: Iterable[Row | DamagedRow]) -> None:
        """Several rows, in order."""
        for row in rows:
            self.append(row)

    def __len__(self) -> int:
        """Messages appended, readable or damaged."""
        return self.readable + len(self.damaged)

    def table(self) -> Table:
        """Every readable row, in arrival order, as one table."""
        if self._pending or not self._tables:
            self._tables.append(self._pack(self._pending))
            self._pending = []
        if len(self._tables) > 1:
            self._tables = [_concatenated(self._tables)]
        return self._tables[0]


def _concatenated(tables: list[Table]) -> Table:
    """The rows of `tables` one after the other (same columns, same dtypes)."""
    import numpy as np

    from syncaudit.columns.table import Table

    names = list(tables[0].columns)
    return Table(
        {name: np.concatenate([t[name] for t in tables]) for name in names},
        sum(len(t) for t in tables),
    )
