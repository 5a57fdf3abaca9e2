"""Our controller's replay equals the plain frame-at-a-time loop (np.median each frame) bit for bit."""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest

from syncaudit.analysis.feedforward import FeedForwardConfig, _median, replay_feedforward


def _reference(
    err: list[float], applied: list[float], exposure: list[float], config: FeedForwardConfig
) -> tuple[list[float], list[float], int]:
    """The controller as docs/advice.md states it, one frame at a time (np.median)."""
    base = applied[0] + exposure[0] / 2.0
    window: deque[float] = deque(maxlen=config.window_frames)
    delays, errors, adjustments = [], [], 0
    for i in range(len(err)):
        if i == 0:
            delay = applied[0]
        else:
            trend = exposure[i - 1] - exposure[i - 2] if i >= 2 else 0.0
            delay = base - (exposure[i - 1] + config.trend_gain * trend) / 2.0
        corrected = err[i] + (delay - applied[i])
        delays.append(delay)
        errors.append(corrected)
        window.append(corrected)
        if len(window) == config.window_frames:
            median = float(np.median(list(window)))
            if abs(median) > config.deadband_ns:
                base -= median
                adjustments += 1
                window.clear()
    return delays, errors, adjustments


def test_window_median_equals_numpys_bit_for_bit() -> None:
    rng = np.random.default_rng(7)
    for size in range(1, 22):
        for _ in range(200):
            values = (rng.normal(size=size) * 1e5).round(1).tolist()
            assert _median(values) == float(np.median(values))


@pytest.mark.parametrize("n", [1, 2, 3, 37, 500, 4000])
@pytest.mark.parametrize(
    "config",
    [(1, 50_000, 0.0), (2, 50_000, 0.0), (5, 50_000, 0.0), (10, 100_000, 0.5), (20, 200_000, 1.0)],
)
def test_replay_is_the_frame_loop_bit_for_bit(n: int, config: tuple[int, int, float]) -> None:
    """Drifting bias, jitter, steps and a tunnel's exposure ramp: every delay, error and
    the number of changes equal the frame-at-a-time controller's exactly."""
    rng = np.random.default_rng(n)
    t = np.arange(n, dtype=np.float64)
    exposure = 2e6 + 10e6 * (np.clip((t - n * 0.3) / 40, 0, 1) - np.clip((t - n * 0.6) / 40, 0, 1))
    exposure += rng.normal(size=n) * 2e4
    applied = 1e7 + np.where(t > n / 2, 3e5, 0.0) + rng.normal(size=n) * 1e3
    error = 2e5 * np.sin(t / 97) + rng.normal(size=n) * 8e4 + exposure / 2
    cfg = FeedForwardConfig(*config)
    replay = replay_feedforward(error, applied, exposure, cfg)
    delays, errors, adjustments = _reference(
        error.tolist(), applied.tolist(), exposure.tolist(), cfg
    )
    assert replay.delays_ns.tolist() == delays
    assert replay.errors_ns.tolist() == errors
    assert replay.adjustments == adjustments
    if n >= 500:
        assert adjustments > 3  # the case exercises the bias loop


def test_replay_moves_the_base_by_the_window_median() -> None:
    """A constant 300 us late error is removed after one window, once (dead band 100 us)."""
    n = 40
    error = np.full(n, 300_000.0)
    applied = np.full(n, 10_000_000.0)
    exposure = np.full(n, 2_000_000.0)
    replay = replay_feedforward(error, applied, exposure, FeedForwardConfig(5, 100_000, 0.0))
    assert replay.adjustments == 1
    assert replay.errors_ns[:5].tolist() == [300_000.0] * 5
    assert replay.errors_ns[5:].tolist() == [0.0] * (n - 5)
    assert replay.delays_ns[5] == 10_000_000.0 - 300_000.0


def _exhaustive(
    error: np.ndarray, applied: np.ndarray, exposure: np.ndarray
) -> tuple[tuple[int, int, float], list[float]]:
    """The grid's choice with every setting replayed in full (the rule as documented)."""
    import itertools
    import math

    from syncaudit.analysis import feedforward as ff

    best, best_key = None, (math.inf, math.inf, math.inf)
    for setting in itertools.product(ff.WINDOWS, ff.DEADBANDS_NS, ff.TREND_GAINS):
        replay = replay_feedforward(error, applied, exposure, FeedForwardConfig(*setting))
        var = replay.error_var_ns2
        key = (
            round(replay.error_mean_ns, -2),
            var if math.isfinite(var) else math.inf,
            float(replay.adjustments),
        )
        if best is None or key < best_key:
            best, best_key = (setting, replay.errors_ns.tolist()), key
    assert best is not None
    return best


@pytest.mark.parametrize("case", ["tunnel", "calm", "constant", "step"])
def test_the_pruned_grid_chooses_what_the_full_grid_chooses(case: str) -> None:
    """Settings stopped early (Eq. 5 surely worse) never change the choice or its replay."""
    from syncaudit.analysis.feedforward import best_feedforward

    rng = np.random.default_rng(11)
    n = 3000
    t = np.arange(n, dtype=np.float64)
    exposure = np.full(n, 2e6)
    if case == "tunnel":
        exposure += 10e6 * (np.clip((t - 900) / 60, 0, 1) - np.clip((t - 1800) / 60, 0, 1))
    applied = np.full(n, 1e7)
    error = {
        "tunnel": exposure / 2 + rng.normal(size=n) * 6e4,
        "calm": rng.normal(size=n) * 3e4,
        "constant": np.full(n, 2.5e5),
        "step": np.where(t > n / 3, 4e5, -1e5) + rng.normal(size=n) * 2e4,
    }[case]
    chosen = best_feedforward(error, applied, exposure)
    setting, errors = _exhaustive(error, applied, exposure)
    c = chosen.config
    assert (c.window_frames, c.deadband_ns, c.trend_gain) == setting
    assert chosen.errors_ns.tolist() == errors
