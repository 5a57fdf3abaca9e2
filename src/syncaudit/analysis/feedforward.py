"""Our delay controller: exposure feed-forward plus a dead-band bias loop, replayed per camera.

The seed's controller (`analysis.controller`) waits until the window's Eq. 5 crosses a
threshold and then recomputes Eq. 2 from running averages: in a tunnel it acts a window
late and, because the average still holds the old light, lands off and acts again. Ours
splits the error into what the driver knows before the trigger and what it does not:

* feed-forward: the exposure the camera is about to use moves the mid-exposure by half of
  it, so each trigger's delay is `base - t5_pred / 2`, with t5_pred the last frame's
  exposure plus `trend_gain` times its last change (the auto-exposure's trend);
* bias loop: what remains is a constant (a mis-measured latency, a wrong zero) plus
  quantisation and jitter no delay removes. The median signed error of the last
  `window_frames` frames (the median: quantisation to packets is uniform, not Gaussian)
  is subtracted from `base` only when it leaves a dead band of `deadband_ns`, and the
  window restarts after each change, so jitter never moves the delay (hysteresis).

The replay follows `analysis.replay`: a frame's error moves one-for-one with its delay.
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from syncaudit.analysis.stats import error_mean, error_variance

__all__ = ["FeedForwardConfig", "FeedForwardReplay", "best_feedforward", "replay_feedforward"]


@dataclass(frozen=True, slots=True)
class FeedForwardConfig:
    """Tuning of our controller."""

    window_frames: int = 10
    """Frames of the bias loop's median (since start or the last change)."""
    deadband_ns: int = 100_000
    """The bias loop moves the delay only when the window's median error exceeds this."""
    trend_gain: float = 0.0
    """0: predict the last frame's exposure; 1: extrapolate its last change in full."""

    def to_dict(self) -> dict[str, float | int]:
        """JSON form (microseconds)."""
        return {
            "window_frames": self.window_frames,
            "deadband_us": self.deadband_ns / 1e3,
            "trend_gain": self.trend_gain,
        }


@dataclass(frozen=True, slots=True)
class FeedForwardReplay:
    """The recorded frames had our controller set each trigger's delay."""

    config: FeedForwardConfig
    delays_ns: NDArray[np.float64]
    """Per input frame, the delay our controller would have used."""
    errors_ns: NDArray[np.float64]
    """Per input frame, the signed error with that delay."""
    adjustments: int
    """Changes of the bias loop (the feed-forward moves the delay every frame)."""

    @property
    def error_mean_ns(self) -> float:
        """Eq. 5 over the replayed frames."""
        return error_mean(np.abs(self.errors_ns))

    @property
    def error_var_ns2(self) -> float:
        """Eq. 6 over the replayed frames."""
        return error_variance(np.abs(self.errors_ns))


def replay_feedforward(
    error_ns: NDArray[np.float64],
    applied_ns: NDArray[np.float64],
    exposure_ns: NDArray[np.float64],
    config: FeedForwardConfig,
) -> FeedForwardReplay:
    """Run our controller over one camera's paired frames, in order (finite inputs).

    The first frame keeps its recorded delay (nothing is known before it); `base` starts
    so that the feed-forward reproduces it.
    """
    n = len(error_ns)
    delays = np.empty(n)
    errors = np.empty(n)
    if not n:
        return FeedForwardReplay(config, delays, errors, 0)
    err, applied, exposure = error_ns.tolist(), applied_ns.tolist(), exposure_ns.tolist()
    base = applied[0] + exposure[0] / 2.0
    gain, band, size = config.trend_gain, config.deadband_ns, config.window_frames
    window: deque[float] = deque(maxlen=size)
    adjustments = 0
    for i in range(n):
        if i == 0:
            delay = applied[0]
        else:
            trend = exposure[i - 1] - exposure[i - 2] if i >= 2 else 0.0
            delay = base - (exposure[i - 1] + gain * trend) / 2.0
        corrected = err[i] + (delay - applied[i])
        delays[i] = delay
        errors[i] = corrected
        window.append(corrected)
        if len(window) == size:
            median = _median(window)
            if abs(median) > band:
                base -= median
                adjustments += 1
                window.clear()
    return FeedForwardReplay(config, delays, errors, adjustments)


def _median(values: deque[float]) -> float:
    """np.median of a few floats, bit for bit (the middle pair's sum halved), ~20x faster:
    the replay takes one per frame for each of the grid's 27 settings."""
    ordered = sorted(values)
    middle = len(ordered) // 2
    if len(ordered) % 2:
        return ordered[middle]
    return (ordered[middle - 1] + ordered[middle]) / 2.0


WINDOWS = (5, 10, 20)
DEADBANDS_NS = (50_000, 100_000, 200_000)
TREND_GAINS = (0.0, 0.5, 1.0)


def best_feedforward(
    error_ns: NDArray[np.float64],
    applied_ns: NDArray[np.float64],
    exposure_ns: NDArray[np.float64],
) -> FeedForwardReplay:
    """Our controller with the parameters (of a small grid) that give this log the lowest
    Eq. 5, ties broken by Eq. 6 then by the fewest bias changes."""
    best: FeedForwardReplay | None = None
    best_key = (math.inf, math.inf, math.inf)
    for window, band, gain in itertools.product(WINDOWS, DEADBANDS_NS, TREND_GAINS):
        replay = replay_feedforward(
            error_ns, applied_ns, exposure_ns, FeedForwardConfig(window, band, gain)
        )
        var = replay.error_var_ns2
        key = (
            round(replay.error_mean_ns, -2),  # 0.1 us: prefer the calmer among equals
            var if math.isfinite(var) else math.inf,
            float(replay.adjustments),
        )
        if best is None or key < best_key:
            best, best_key = replay, key
    assert best is not None
    return best
