"""The method's statistics: Eq. 5 mean and Eq. 6 unbiased variance, whole and rolling."""

from __future__ import annotations

import numpy as np
import pandas as pd
from numpy.typing import NDArray


def error_mean(t_error: NDArray[np.float64]) -> float:
    """Eq. 5: mean of t_error over the N frames given."""
    return float(np.mean(t_error)) if t_error.size else float("nan")


def error_variance(t_error: NDArray[np.float64]) -> float:
    """Eq. 6: (sum(t^2)/N - mean^2) * N/(N-1), exactly as the method writes it."""
    n = t_error.size
    if n < 2:
        return float("nan")
    mean = float(np.mean(t_error))
    return (float(np.mean(np.square(t_error))) - mean**2) * n / (n - 1)


def rolling_mean(values: NDArray[np.float64], window: int) -> NDArray[np.float64]:
    """Running average of the last `window` values (fewer at the start); Eq. 3 and Eq. 5."""
    out: NDArray[np.float64] = (
        pd.Series(values).rolling(window, min_periods=1).mean().to_numpy(np.float64)
    )
    return out


def rolling_variance(values: NDArray[np.float64], window: int) -> NDArray[np.float64]:
    """Eq. 6 over the last `window` values (NaN until two are there)."""
    out: NDArray[np.float64] = (
        pd.Series(values).rolling(window, min_periods=2).var(ddof=1).to_numpy(np.float64)
    )
    return out
