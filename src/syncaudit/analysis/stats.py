"""The method's statistics: Eq. 5 mean and Eq. 6 unbiased variance, whole and rolling."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from syncaudit.analysis.rolling import rolling_mean, rolling_variance

__all__ = ["error_mean", "error_variance", "rolling_mean", "rolling_variance"]


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
