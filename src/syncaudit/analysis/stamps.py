"""Exact int64 nanosecond stamps with a marker for missing ones, and their differences.

Epoch nanoseconds (~1.7e18) do not fit a float64 mantissa: as floats they move in 256 ns
steps. Stamps therefore stay int64 (`MISSING_NS` where a log does not have one) and only
differences between two stamps, which are small, become float64 (NaN where either is
missing). Tables (`syncaudit.columns.table.Table`) hold them so; DataFrames handed out
have them as pandas nullable `Int64`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from syncaudit.columns.table import MISSING, Table

if TYPE_CHECKING:
    import pandas as pd

MISSING_NS = MISSING
"""Marker of a stamp the log does not hold (never a real epoch time)."""


def stamps_ns(table: Table, name: str) -> NDArray[np.int64]:
    """A stamp column as int64 with `MISSING_NS` for missing values (or an absent column)."""
    if name not in table:
        return np.full(len(table), MISSING_NS, dtype=np.int64)
    values: NDArray[np.int64] = np.asarray(table[name], dtype=np.int64)
    return values


def present(stamps: NDArray[np.int64]) -> NDArray[np.bool_]:
    """Which stamps are there."""
    there: NDArray[np.bool_] = np.not_equal(stamps, MISSING_NS)
    return there


def delta_ns(later: NDArray[np.int64], earlier: NDArray[np.int64]) -> NDArray[np.float64]:
    """`later - earlier` computed in int64, as float64 with NaN where either is missing."""
    ok = present(later) & present(earlier)
    out = np.full(later.shape, np.nan, dtype=np.float64)
    out[ok] = (later[ok] - earlier[ok]).astype(np.float64)
    return out


def values_ns(table: Table, name: str) -> NDArray[np.float64]:
    """A small nanosecond quantity (a duration, a delay) as float64, NaN where missing."""
    stamps = stamps_ns(table, name)
    out = stamps.astype(np.float64)
    out[~present(stamps)] = np.nan
    return out


def nullable(stamps: NDArray[np.int64]) -> pd.api.extensions.ExtensionArray:
    """Stamps as a pandas `Int64` array (<NA> where missing); imports pandas."""
    import pandas as pd

    values = np.asarray(stamps, dtype=np.int64)
    return pd.arrays.IntegerArray(values.copy(), ~present(values))
