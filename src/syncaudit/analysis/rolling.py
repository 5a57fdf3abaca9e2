"""Rolling mean and variance over the last `window` values, without pandas.

The audit's figures (Eq. 3's running exposure, Eq. 5/6 over a window) were pandas'
`Series.rolling(window)`: these give the same float64 results bit for bit, so reports
stay identical. The mean of integer-valued data (nanoseconds) is exact and vectorised:
each window's sum is an exact int64 and one division rounds it, as pandas' compensated
sum does when no partial sum rounds. Other data, and every variance, run the online
algorithms pandas uses (Kahan-compensated sums; Welford's variance with the window
recomputed after a possible cancellation), one value at a time.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

EXACT_LIMIT = float(2**53)
"""Integers below this are exact in float64; window sums must stay below it."""
INV_COND_TOL = float(np.finfo(np.float64).eps) * 1e3
"""A window's sum of squares shrinking below this share of its previous value: recompute."""


def rolling_mean(values: NDArray[np.float64], window: int) -> NDArray[np.float64]:
    """Mean of the non-NaN values among the last `window` (NaN where there are none).

    Non-negative whole numbers (durations, absolute errors in ns) take the exact path.
    """
    finite = values[~np.isnan(values)]
    integral = bool(np.all(finite == np.round(finite))) and not np.any(np.signbit(finite))
    if integral and (not finite.size or float(finite.max()) * window < EXACT_LIMIT):
        return _exact_mean(values, window)
    return _online_mean(values, window)


def _exact_mean(values: NDArray[np.float64], window: int) -> NDArray[np.float64]:
    ok = ~np.isnan(values)
    sums = np.concatenate(([0], np.cumsum(np.where(ok, values, 0.0).astype(np.int64))))
    counts = np.concatenate(([0], np.cumsum(ok)))
    end = np.arange(1, values.size + 1)
    start = np.maximum(end - window, 0)
    total, n = sums[end] - sums[start], counts[end] - counts[start]
    out = np.full(values.size, np.nan)
    has = n > 0
    out[has] = total[has].astype(np.float64) / n[has]
    return out


def _online_mean(values: NDArray[np.float64], window: int) -> NDArray[np.float64]:
    """Kahan-compensated running sum with values leaving and entering the window."""
    vals = values.tolist()
    out = np.empty(len(vals))
    nobs = negative = same = 0
    total = comp_add = comp_remove = 0.0
    last = math.nan
    for i in range(len(vals)):
        start = max(0, i + 1 - window)
        if i == 0 or start >= i:  # a fresh window
            last, same, nobs, negative = vals[start], 0, 0, 0
            total = comp_add = comp_remove = 0.0
            leaving, entering = range(0), range(start, i + 1)
        else:
            leaving, entering = range(max(0, i - window), start), range(i, i + 1)
        for j in leaving:
            v = vals[j]
            if v == v:
                nobs -= 1
                y = -v - comp_remove
                t = total + y
                comp_remove = t - total - y
                total = t
                negative -= math.copysign(1.0, v) < 0
        for j in entering:
            v = vals[j]
            if v == v:
                nobs += 1
                y = v - comp_add
                t = total + y
                comp_add = t - total - y
                total = t
                negative += math.copysign(1.0, v) < 0
                same = same + 1 if v == last else 1
                last = v
        out[i] = _mean_of(total, nobs, negative, same, last)
    return out


def _mean_of(total: float, nobs: int, negative: int, same: int, last: float) -> float:
    if nobs <= 0:
        return math.nan
    if same >= nobs:  # one value repeated: exactly that value
        return last
    mean = total / nobs
    if (negative == 0 and mean < 0) or (negative == nobs and mean > 0):
        return 0.0
    return mean


def rolling_variance(values: NDArray[np.float64], window: int) -> NDArray[np.float64]:
    """Unbiased variance of the non-NaN values among the last `window` (NaN below two)."""
    vals = values.tolist()
    out = np.empty(len(vals))
    state = _Welford()
    for i in range(len(vals)):
        start = max(0, i + 1 - window)
        fresh = i == 0 or start >= i
        if not fresh:
            for j in range(max(0, i - window), start):
                state.remove(vals[j])
            state.add(vals[i])
        if fresh or state.unstable:
            state = _Welford()
            for j in range(start, i + 1):
                state.add(vals[j])
            state.unstable = False
        n = state.nobs
        out[i] = state.ssqdm / (n - 1.0) if n >= 2 else math.nan
    return out


class _Welford:
    """Welford's running mean and sum of squared deviations, Kahan-compensated."""

    __slots__ = ("comp_add", "comp_remove", "mean", "nobs", "ssqdm", "unstable")

    def __init__(self) -> None:
        self.nobs = 0.0
        self.mean = self.ssqdm = self.comp_add = self.comp_remove = 0.0
        self.unstable = False

    def add(self, v: float) -> None:
        if v != v:
            return
        before = self.ssqdm
        self.nobs += 1
        prev_mean = self.mean - self.comp_add
        y = v - self.comp_add
        t = y - self.mean
        self.comp_add = t + self.mean - y
        self.mean = self.mean + t / self.nobs
        self.ssqdm = self.ssqdm + (v - prev_mean) * (v - self.mean)
        if before * INV_COND_TOL > self.ssqdm:
            self.unstable = True

    def remove(self, v: float) -> None:
        if v != v:
            return
        before = self.ssqdm
        self.nobs -= 1
        if not self.nobs:
            self.mean = self.ssqdm = 0.0
            self.unstable = False
            return
        prev_mean = self.mean - self.comp_remove
        y = v - self.comp_remove
        t = y - self.mean
        self.comp_remove = t + self.mean - y
        self.mean = self.mean - t / self.nobs
        self.ssqdm = self.ssqdm - (v - prev_mean) * (v - self.mean)
        if before * INV_COND_TOL > self.ssqdm:
            self.unstable = True
