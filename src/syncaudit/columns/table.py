"""`Table`: equal-length numpy columns, the audit's tables without pandas.

The analysis runs on these; pandas is imported only to hand a table out as a DataFrame
(`to_pandas`: the CSV, Parquet and HTML outputs, `AuditResult.frames()`), so an audit that
writes none of those never imports it (~0.2 s of start-up).

Column kinds, by the pandas dtype the DataFrame gives them:

| dtype | numpy column |
| --- | --- |
| `int64` | int64 |
| `Int64` (nullable) | int64, `MISSING` where missing |
| `string` | object: `str`, or None where missing |
| `float64`, `bool` | float64 (NaN where missing), bool |
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    import pandas as pd

MISSING = np.iinfo(np.int64).min
"""Marker of a missing value in an int64 column (never a real stamp or sequence number)."""


def int_column(values: Iterable[int | None]) -> NDArray[np.int64]:
    """Python ints (None where missing) as an int64 column with `MISSING`."""
    return np.array([MISSING if v is None else v for v in values], dtype=np.int64)


def str_column(values: Sequence[str | None]) -> NDArray[np.object_]:
    """Strings (None where missing) as an object column."""
    out = np.empty(len(values), dtype=object)
    out[:] = values
    return out


class Table:
    """Named numpy columns of one length, in insertion order."""

    __slots__ = ("columns", "length")

    def __init__(self, columns: Mapping[str, NDArray[Any]], length: int | None = None) -> None:
        self.columns: dict[str, NDArray[Any]] = dict(columns)
        lengths = {len(c) for c in self.columns.values()}
        if length is None:
            length = lengths.pop() if lengths else 0
        if lengths - {length}:
            raise ValueError(f"columns of lengths {sorted(lengths)} in a table of {length} rows")
        self.length = length

    def __len__(self) -> int:
        return self.length

    def __contains__(self, name: object) -> bool:
        return name in self.columns

    def __getitem__(self, name: str) -> NDArray[Any]:
        return self.columns[name]

    @property
    def empty(self) -> bool:
        """No rows."""
        return self.length == 0

    def take(self, rows: NDArray[np.intp] | NDArray[np.int64]) -> Table:
        """The rows at these positions, in this order."""
        return Table({k: v[rows] for k, v in self.columns.items()}, len(rows))

    def with_columns(self, columns: Mapping[str, NDArray[Any]]) -> Table:
        """A copy with these columns added or replaced (same length)."""
        return Table({**self.columns, **columns}, self.length)

    def to_pandas(self, dtypes: Mapping[str, str]) -> pd.DataFrame:
        """The columns named in `dtypes` (in its order) as a DataFrame of those dtypes."""
        import pandas as pd

        return pd.DataFrame(
            {name: _series(self.columns[name], dtype) for name, dtype in dtypes.items()}
        )


def _series(values: NDArray[Any], dtype: str) -> Any:
    """One column as the pandas array of `dtype`."""
    import pandas as pd

    if dtype == "Int64":
        data = np.asarray(values, dtype=np.int64)
        return pd.arrays.IntegerArray(data.copy(), data == MISSING)
    if dtype == "string":
        return pd.array(values.tolist(), dtype="string")
    return np.asarray(values, dtype=dtype)
