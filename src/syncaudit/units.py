"""Unit conversions for reports: int64 ns inside, microseconds (or None) in JSON."""

from __future__ import annotations

import math
from typing import Any


def finite_or_none(value: float | None) -> float | None:
    """The value as a float, or None where it is missing or not finite (JSON has no NaN)."""
    return None if value is None or not math.isfinite(value) else float(value)


def ns_to_us(value_ns: float | None) -> float | None:
    """Nanoseconds as microseconds, or None where missing or not finite."""
    value = finite_or_none(value_ns)
    return None if value is None else value / 1e3


def json_ready(value: Any) -> Any:
    """Nested dicts/lists/tuples with every non-finite float as None (JSON has no NaN)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: json_ready(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_ready(v) for v in value]
    return value
