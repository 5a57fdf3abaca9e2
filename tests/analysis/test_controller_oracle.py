"""DelayController against a brute-force oracle that recomputes every window from history.

The controller keeps exact integer sums of its error window and sums its input window
only when an adjustment needs Eq. 2; the oracle below keeps every frame and recomputes
each window from scratch per frame, as the method states it (Eq. 2, 3, 5, 6, thresholds,
window cleared after an adjustment). Delays, adjustments and window statistics must be
identical, frame by frame, for both modes, any window, with and without an initial delay.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from syncaudit.analysis.controller import (
    Adjustment,
    ControllerConfig,
    DelayController,
    FrameObservation,
    WindowStats,
    eq2_delay_ns,
)


class Oracle:
    """The controller of the method, recomputed from the full history at every frame."""

    def __init__(self, config: ControllerConfig, initial_delay_ns: int | None) -> None:
        self.config = config
        self.inputs: list[tuple[int, ...]] = []
        self.errors: list[int] = []  # since the last adjustment
        self.delay = initial_delay_ns
        self.adjustments: list[Adjustment] = []
        self.last_stats: WindowStats | None = None

    def stats(self) -> WindowStats:
        window = [abs(e) for e in self.errors[-self.config.window_frames :]]
        signed = self.errors[-self.config.window_frames :]
        n = len(window)
        s, s2 = sum(window), sum(v * v for v in window)
        return WindowStats(
            frames=n,
            error_mean_ns=s / n if n else math.nan,
            error_var_ns2=(n * s2 - s * s) / (n * (n - 1)) if n >= 2 else math.nan,
            signed_error_mean_ns=sum(signed) / n if n else math.nan,
        )

    def means(self) -> list[float]:
        window = self.inputs[-self.config.window_frames :]
        return [sum(row[j] for row in window) / len(window) for j in range(6)]

    def clamp(self, delay: float) -> int:
        return min(max(0, round(delay)), max(0, round(self.means()[5])))

    def eq2(self) -> float:
        t1, t2, t3, t4, t5, rot = self.means()
        return eq2_delay_ns(rot, t1, t2, t3, t4, t5)

    def adjust(self, index: int, new: int, reason: str, stats: WindowStats) -> int:
        old = new if self.delay is None else self.delay
        self.adjustments.append(Adjustment(index, old, new, reason, stats))  # type: ignore[arg-type]
        self.delay, self.errors = new, []
        return new

    def update(self, index: int, frame: FrameObservation) -> int:
        f = frame
        self.inputs.append((f.t1_ns, f.t2_ns, f.t3_ns, f.t4_ns, f.exposure_ns, f.t_rotate_ns))
        self.errors.append(f.error_ns)
        stats = self.last_stats = self.stats()
        if self.delay is None:
            return self.adjust(index, self.clamp(self.eq2()), "initial", stats)
        if stats.frames < self.config.min_frames:
            return self.delay
        over_mean = stats.error_mean_ns > self.config.mean_error_threshold_ns
        over_var = stats.error_var_ns2 > self.config.variance_threshold_ns2
        if not (over_mean or over_var):
            return self.delay
        reason = "mean+variance" if over_mean and over_var else "mean" if over_mean else "variance"
        if self.config.mode == "recompute":
            new = self.clamp(self.eq2())
        else:
            new = self.clamp(self.delay - stats.signed_error_mean_ns)
        return self.adjust(index, new, reason, stats)


def _same_stats(a: WindowStats | None, b: WindowStats | None) -> bool:
    if a is None or b is None:
        return a is b
    pairs = zip(
        (a.frames, a.error_mean_ns, a.error_var_ns2, a.signed_error_mean_ns),
        (b.frames, b.error_mean_ns, b.error_var_ns2, b.signed_error_mean_ns),
        strict=True,
    )
    return all(x == y or (math.isnan(x) and math.isnan(y)) for x, y in pairs)


@pytest.mark.parametrize("mode", ["recompute", "shift"])
@pytest.mark.parametrize(("window", "min_frames"), [(2, 2), (3, 2), (10, 10), (10, 4)])
@pytest.mark.parametrize("initial", [None, 20_000_000])
def test_controller_equals_oracle(
    mode: str, window: int, min_frames: int, initial: int | None
) -> None:
    config = ControllerConfig(
        window_frames=window,
        min_frames=min_frames,
        mode=mode,  # type: ignore[arg-type]
        mean_error_threshold_ns=200_000,
        variance_threshold_ns2=3.0e10,
    )
    rng = np.random.default_rng(window * 7 + min_frames + (initial is None))
    controller, oracle = DelayController(config, initial), Oracle(config, initial)
    for index in range(600):
        t = rng.integers(10_000, 500_000, 4)
        regime = (index // 50) % 3  # calm, biased, unstable
        error = rng.normal([0.0, 400_000.0, 0.0][regime], [30_000.0, 30_000.0, 600_000.0][regime])
        values = [
            *t.tolist(),
            int(rng.integers(100_000, 9_000_000)),
            round(float(error)),
            int(rng.integers(100_000, 60_000_000)),
        ]
        if index % 7 == 0:  # numpy integers, as a caller might pass
            values = [np.int64(v) for v in values]
        frame = FrameObservation(*values)
        want = oracle.update(index, FrameObservation(*(int(v) for v in values)))
        assert controller.update(frame) == want == controller.delay_ns, index
        assert _same_stats(controller.last_stats, oracle.last_stats), index
        assert controller.frames_seen == index + 1
    assert len(controller.adjustments) == len(oracle.adjustments) >= 5
    for got, exp in zip(controller.adjustments, oracle.adjustments, strict=True):
        got_key = (got.frame_index, got.old_delay_ns, got.new_delay_ns, got.reason)
        assert got_key == (exp.frame_index, exp.old_delay_ns, exp.new_delay_ns, exp.reason)
        assert _same_stats(got.stats, exp.stats)
    means = oracle.means()
    assert controller.mean_t5_ns() == means[4]
    assert controller.eq2_delay_ns() == oracle.eq2()
    assert _same_stats(controller.window_stats(), oracle.stats())
