"""What a camera's trigger design can reach at best: its error floor, measured on the log.

A delay (constant or per frame) can remove the error's constant part and the half
exposure that moves the mid-exposure; it cannot remove where the trigger packet happened
to sit relative to the zero crossing (a trigger fired from a packet is quantised to the
packet period, about period / sqrt(12) standard deviation) nor the jitter of the trigger
chain t1..t4. The floor is Eq. 5/6 of what is left once both removable parts are taken
out of the recorded errors: `e - t5 / 2 - (d - median d)` (d: each frame's applied delay,
so a rig already compensating per frame is not charged for it), centred on its median
(the centre that minimises Eq. 5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from syncaudit.analysis.stats import error_mean, error_variance
from syncaudit.units import finite_or_none, ns_to_us

__all__ = ["ErrorFloor", "error_floor"]

PACKET_TRIGGERED_MIN_NS = 1_000.0
"""A trigger-packet phase spread above 1 us: the trigger is quantised to packets."""


@dataclass(frozen=True, slots=True)
class ErrorFloor:
    """Eq. 5/6 a perfect correction would leave, and its two measured sources."""

    error_mean_ns: float
    error_var_ns2: float
    quantisation_ns: float
    """Standard deviation of the trigger packet's phase to the zero crossing (NaN unknown)."""
    jitter_ns: float
    """Standard deviation of the trigger chain t1 + t2 + t3 + t4 (NaN unknown)."""

    @property
    def trigger(self) -> str:
        """'packet' (quantised to LiDAR packets), 'time' (no packet spread) or 'unknown'."""
        if not math.isfinite(self.quantisation_ns):
            return "unknown"
        return "packet" if self.quantisation_ns > PACKET_TRIGGERED_MIN_NS else "time"

    def to_dict(self) -> dict[str, Any]:
        """JSON form (microseconds)."""
        return {
            "error_mean_us": ns_to_us(self.error_mean_ns),
            "error_var_us2": finite_or_none(self.error_var_ns2 / 1e6),
            "quantisation_us": ns_to_us(self.quantisation_ns),
            "jitter_us": ns_to_us(self.jitter_ns),
            "trigger": self.trigger,
        }


def _std(values: NDArray[np.float64]) -> float:
    finite = values[np.isfinite(values)]
    return float(finite.std(ddof=1)) if finite.size >= 2 else math.nan


def error_floor(
    error_ns: NDArray[np.float64],
    exposure_ns: NDArray[np.float64],
    phase_ns: NDArray[np.float64],
    chain_ns: NDArray[np.float64],
    applied_ns: NDArray[np.float64] | None = None,
) -> ErrorFloor:
    """The floor of one camera from its paired frames' signed error, exposure, trigger
    packet phase and trigger-chain latency (t1 + t2 + t3 + t4), and the delay each frame
    was triggered with (`applied_ns`, NaN or None where unknown: taken as constant)."""
    residual = error_ns - exposure_ns / 2.0
    if applied_ns is not None and np.isfinite(applied_ns).any():
        known = np.isfinite(applied_ns)
        residual = residual - np.where(known, applied_ns - np.median(applied_ns[known]), 0.0)
    residual = residual[np.isfinite(residual)]
    centred = np.abs(residual - np.median(residual)) if residual.size else residual
    return ErrorFloor(error_mean(centred), error_variance(centred), _std(phase_ns), _std(chain_ns))
