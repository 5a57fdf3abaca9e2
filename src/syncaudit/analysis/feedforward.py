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
    so that the feed-forward reproduces it. Vectorised by blocks: between two changes of
    the bias loop `base` is constant, so a block's delays, errors and window medians are
    array operations (the same IEEE operations, in the same order, as one frame at a time);
    after a change the block is recomputed from the next frame.
    """
    n = len(error_ns)
    delays = np.empty(n)
    errors = np.empty(n)
    if not n:
        return FeedForwardReplay(config, delays, errors, 0)
    err = np.asarray(error_ns, dtype=np.float64)
    applied = np.asarray(applied_ns, dtype=np.float64)
    exposure = np.asarray(exposure_ns, dtype=np.float64)
    feed = _feed_forward_ns(exposure, config.trend_gain)
    base = float(applied[0]) + float(exposure[0]) / 2.0
    band, size = config.deadband_ns, config.window_frames
    adjustments = 0
    start = 0  # first frame of the bias loop's current window
    i = 0
    block = _MIN_BLOCK
    while i < n:
        hi = min(n, i + block)
        delay = base - feed[i:hi]
        if i == 0:
            delay[0] = applied[0]
        delays[i:hi] = delay
        errors[i:hi] = err[i:hi] + (delay - applied[i:hi])
        first_end = max(i, start + size - 1)
        if first_end < hi:
            medians = _window_medians(errors[first_end - size + 1 : hi], size)
            hit = np.flatnonzero(np.abs(medians) > band)
            if hit.size:
                base -= float(medians[hit[0]])
                adjustments += 1
                start = i = first_end + int(hit[0]) + 1
                block = _MIN_BLOCK
                continue
        i = hi
        block = min(2 * block, _MAX_BLOCK)
    return FeedForwardReplay(config, delays, errors, adjustments)


_MIN_BLOCK = 32
_MAX_BLOCK = 1024
"""Frames per vectorised block: small right after a change (the rest of a block is
recomputed after one), doubling while the loop holds still."""


def _feed_forward_ns(exposure: NDArray[np.float64], gain: float) -> NDArray[np.float64]:
    """Per frame, half the predicted exposure: the last frame's plus `gain` times its last
    change (no change known before the second frame); frame 0's is unused."""
    feed = np.zeros(exposure.size)
    if exposure.size > 1:
        trend = np.zeros(exposure.size - 1)
        trend[1:] = exposure[1:-1] - exposure[:-2]
        feed[1:] = (exposure[:-1] + gain * trend) / 2.0
    return feed


def _window_medians(values: NDArray[np.float64], size: int) -> NDArray[np.float64]:
    """The median of every `size` consecutive values, as np.median gives it bit for bit
    (the middle value, or the middle pair's sum halved)."""
    ordered = np.sort(np.lib.stride_tricks.sliding_window_view(values, size), axis=1)
    middle = size // 2
    if size % 2:
        return ordered[:, middle]
    out: NDArray[np.float64] = (ordered[:, middle - 1] + ordered[:, middle]) / 2.0
    return out


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
