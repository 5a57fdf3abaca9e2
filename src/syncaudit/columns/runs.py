"""`run_starts`: where each run of equal values begins in a nondecreasing integer column.

For a sorted column, `np.unique(values, return_index=True)` sorts it again (a stable
argsort) to find what one comparison of neighbours finds: the first index of each
distinct value. The LiDAR tracker asks this of packet and revolution numbers that are
nondecreasing by construction, for every batch of packets, in the audit's parent.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def run_starts(values: NDArray[np.integer]) -> NDArray[np.intp] | None:
    """First index of each run of equal values; None when `values` is empty or not
    nondecreasing (the caller then takes the general path, e.g. `np.unique`).

    For a nondecreasing array the result equals `np.unique(values, return_index=True)[1]`
    and `values[result]` equals its unique values. Neighbours are compared, never
    subtracted, so no difference can wrap round.
    """
    if values.ndim != 1 or values.size == 0 or values.dtype.kind not in "iu":
        return None
    head, tail = values[:-1], values[1:]
    if (tail < head).any():
        return None
    changed = tail != head
    starts = np.empty(np.count_nonzero(changed) + 1, dtype=np.intp)
    starts[0] = 0
    starts[1:] = np.flatnonzero(changed) + 1
    return starts
