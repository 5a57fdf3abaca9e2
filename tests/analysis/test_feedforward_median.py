"""Our controller's window median is numpy's, bit for bit, and the replay is unchanged by it."""

from __future__ import annotations

from collections import deque

import numpy as np

from syncaudit.analysis.feedforward import FeedForwardConfig, _median, replay_feedforward


def test_window_median_equals_numpys_bit_for_bit() -> None:
    rng = np.random.default_rng(7)
    for size in range(1, 22):
        for _ in range(200):
            values = (rng.normal(size=size) * 1e5).round(1).tolist()
            assert _median(deque(values)) == float(np.median(values))


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
