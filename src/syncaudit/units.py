"""Unit conversions for reports: int64 ns inside, microseconds (or None) in JSON."""

from __future__ import annotations

import math


def finite_or_none(value: float | None) -> float | None:
    """The value as a float, or None where it is missing or not finite (JSON has no NaN)."""
    return None if value is None or not math.isfinite(value) else float(value)


def ns_to_us(value_ns: float | None) -> float | None:
    """Nanoseconds as microseconds, or None where missing or not finite."""
    value = finite_or_none(value_ns)
    return None if value is None else value / 1e3
