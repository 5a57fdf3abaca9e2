"""`distinct`: the sorted distinct values of an integer column, without importing numpy.ma.

numpy >= 2.3's `np.unique(values)` (asked for no index, inverse or counts) checks
`np.ma.is_masked(values)` first, which imports `numpy.ma` on first use: ~8 ms of start-up
in the audit's parent and again in every forked reader worker (the Hesai decoder asks once
per message), for arrays that are never masked. A sort and one comparison give the same
values for integers.
"""

from __future__ import annotations

from typing import TypeVar

import numpy as np
from numpy.typing import NDArray

ScalarT = TypeVar("ScalarT", bound=np.generic)


def distinct(values: NDArray[ScalarT]) -> NDArray[ScalarT]:
    """The sorted distinct values of an integer or bool array, flattened (as `np.unique`).

    Raises:
        TypeError: `values` is not of an integer or bool dtype (NaN makes floats differ).
    """
    if values.dtype.kind not in "biu":
        raise TypeError(f"distinct() takes integers, not {values.dtype}")
    ordered = np.sort(values, axis=None)
    if ordered.size < 2:
        return ordered
    keep = np.empty(ordered.size, dtype=bool)
    keep[0] = True
    np.not_equal(ordered[1:], ordered[:-1], out=keep[1:])
    return ordered[keep]
