"""The rolling mean and variance without pandas give pandas' `Series.rolling` results bit
for bit (the reports' Eq. 3/5/6 figures were defined by it): pandas is the reference."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from syncaudit.analysis.rolling import _online_mean, rolling_mean, rolling_variance


def _cases() -> list[tuple[str, np.ndarray, int]]:
    rng = np.random.default_rng(20261130)
    out = []
    for i in range(60):
        n, window = int(rng.integers(0, 400)), int(rng.integers(2, 90))
        kind = ("errors_ns", "floats", "constant_runs", "large_offset", "signed_ints")[i % 5]
        if kind == "errors_ns":  # |error| in whole nanoseconds, as the audit feeds it
            x = np.abs(rng.normal(0, 2e6, n)).round()
        elif kind == "floats":
            x = rng.normal(5.0, 1.0, n)
        elif kind == "constant_runs":  # repeated values: pandas returns them exactly
            x = np.where(rng.random(n) < 0.8, 7.0, rng.integers(0, 3, n).astype(float))
        elif kind == "large_offset":  # Welford's cancellation case: big mean, tiny spread
            x = np.abs(rng.normal(1e9, 5.0, n)).round()
        else:
            x = rng.normal(0, 1e4, n).round()
        x[rng.random(n) < 0.15] = np.nan  # unpaired frames
        out.append((kind, x, window))
    return out


@pytest.mark.parametrize(("kind", "values", "window"), _cases())
def test_rolling_matches_pandas_bit_for_bit(kind: str, values: np.ndarray, window: int) -> None:
    series = pd.Series(values, dtype="float64")
    mean = series.rolling(window, min_periods=1).mean().to_numpy()
    var = series.rolling(window, min_periods=2).var(ddof=1).to_numpy()
    assert np.array_equal(rolling_mean(values, window), mean, equal_nan=True), kind
    assert np.array_equal(_online_mean(values, window), mean, equal_nan=True), kind
    assert np.array_equal(rolling_variance(values, window), var, equal_nan=True), kind


def test_exact_mean_of_whole_nanoseconds() -> None:
    """Window sums of whole numbers are exact: the mean is one rounding of the true one."""
    values = np.array([3.0, 4.0, np.nan, 5.0, 1e15, 1.0])
    expected = [3.0, 3.5, 3.5, 4.5, (1e15 + 5) / 2, (1e15 + 6) / 3]
    assert rolling_mean(values, 3).tolist() == expected
    assert np.isnan(rolling_variance(values, 2)[2])  # one value in the window
