"""The self-adaptive delay controller of the method (part A), as it runs online per camera.

Per frame the camera driver knows the trigger-chain latencies t1..t4, the exposure
duration t5_i, the frame's signed synchronisation error (t_l - t_estimated) and the
alignment time t_rotate = theta / omega. The controller keeps the last N of each in ring
buffers and computes

* Eq. 3  t5 = mean of the last N exposure durations,
* Eq. 2  t_sleep = t_rotate - (t1 + t2 + t3 + t4 + t5 / 2) from running averages,
* Eq. 5  t_error_avg = mean of |error| over the last N frames,
* Eq. 6  t_error_var = (sum(|error|^2) / N - t_error_avg^2) * N / (N - 1),

and adjusts the delay when Eq. 5 exceeds the first threshold or Eq. 6 the second. Sums are
kept as exact Python integers, so Eq. 5/6 are exact rationals turned into floats once, and
the controller is deterministic whatever the order of floating point operations.

After an adjustment the error window is cleared: errors measured with the old delay say
nothing about the new one, and acting on them again would overshoot.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator


class ControllerConfig(BaseModel):
    """Tuning of the self-adaptive delay; defaults assume a 10 Hz LiDAR (600 RPM)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    window_frames: int = Field(default=10, ge=2)
    """N of Eq. 3, 5 and 6. Ten frames is one second at 10 Hz: the running exposure average
    follows a tunnel entry within a second, and averaging ten frames cuts latency jitter by
    about 3x. N >= 2 because Eq. 6 divides by N - 1."""

    mean_error_threshold_ns: int = Field(default=250_000, ge=0)
    """First threshold (Eq. 5). 250 us is 0.9 deg of rotation at 600 RPM; trigger-chain
    jitter of tens of microseconds gives a mean |error| well below it, so the controller
    only acts on a real bias."""

    variance_threshold_ns2: float = Field(default=4.0e10, ge=0.0)
    """Second threshold (Eq. 6), in ns^2: (200 us)^2. The variance of |error| from normal
    jitter of std s is about 0.36 s^2, so this is crossed only by instability (e.g. an
    exposure changing faster than Eq. 3 follows), not by ordinary jitter."""

    mode: Literal["recompute", "shift"] = "recompute"
    """'recompute': new delay from Eq. 2 with fresh running averages (the method's first
    option; follows the light). 'shift': old delay minus the mean signed error of the
    window (corrects biases Eq. 2 cannot see, such as a mis-measured latency)."""

    min_frames: int = Field(default=10, ge=2)
    """Frames observed (since start or since the last adjustment) before thresholds are
    judged; defaults to a full window so Eq. 5/6 are never taken from a handful of frames."""

    @model_validator(mode="after")
    def _min_within_window(self) -> ControllerConfig:
        if self.min_frames > self.window_frames:
            raise ValueError("min_frames must not exceed window_frames")
        return self


@dataclass(frozen=True, slots=True)
class FrameObservation:
    """What the camera driver measured for one frame (all integer nanoseconds)."""

    t1_ns: int
    """240 -> 242: packet captured -> LiDAR driver."""
    t2_ns: int
    """242 -> 244: LiDAR driver -> camera driver."""
    t3_ns: int
    """244 -> 246 minus the applied delay: camera driver -> camera sensor."""
    t4_ns: int
    """246 -> 248: camera told -> exposure starts."""
    exposure_ns: int
    """t5_i, the frame's exposure duration."""
    error_ns: int
    """Signed synchronisation error t_l - t_estimated (positive: camera late)."""
    t_rotate_ns: int
    """theta / omega for this camera, as measured for this revolution."""


@dataclass(frozen=True, slots=True)
class WindowStats:
    """Statistics of the current error window (Eq. 5, Eq. 6 and the signed mean)."""

    frames: int
    error_mean_ns: float
    """Eq. 5: mean of |error|."""
    error_var_ns2: float
    """Eq. 6: unbiased variance of |error|; NaN below two frames."""
    signed_error_mean_ns: float


@dataclass(frozen=True, slots=True)
class Adjustment:
    """One change of the delay and why it happened."""

    frame_index: int
    """0-based index of the observation after which the delay changed."""
    old_delay_ns: int
    new_delay_ns: int
    reason: Literal["mean", "variance", "mean+variance", "initial"]
    stats: WindowStats


def eq5_mean_abs(sum_abs: int, n: int) -> float:
    """Eq. 5 from the exact sum of |error| over n frames."""
    return sum_abs / n if n else float("nan")


def eq6_variance(sum_abs: int, sum_sq: int, n: int) -> float:
    """Eq. 6 from exact sums: (S2/N - (S/N)^2) * N/(N-1) = (N*S2 - S^2) / (N*(N-1))."""
    if n < 2:
        return float("nan")
    return (n * sum_sq - sum_abs * sum_abs) / (n * (n - 1))


def eq2_delay_ns(
    t_rotate_ns: float, t1_ns: float, t2_ns: float, t3_ns: float, t4_ns: float, t5_ns: float
) -> float:
    """Eq. 2: t_sleep = t_rotate - (t1 + t2 + t3 + t4 + t5 / 2)."""
    return t_rotate_ns - (t1_ns + t2_ns + t3_ns + t4_ns + t5_ns / 2.0)


class DelayController:
    """Online self-adaptive trigger delay for one camera (Eq. 2, 3, 5, 6 + thresholds).

    Per frame it only stores the inputs and updates the error window's exact sums: the
    running averages of Eq. 2/3 are summed when an adjustment needs them (exact integer
    sums, so the same values as sums kept per push), and the window's statistics are built
    as objects only when judged over a threshold or asked for.
    """

    def __init__(self, config: ControllerConfig, initial_delay_ns: int | None = None) -> None:
        """`initial_delay_ns` is the delay used until the first adjustment; None: compute
        it by Eq. 2 from the first observation."""
        self.config = config
        self._capacity = config.window_frames
        self._inputs: list[tuple[int, int, int, int, int, int]] = []
        """The last N (t1, t2, t3, t4, t5, t_rotate), a ring: the oldest at `_next`."""
        self._next = 0
        self._errors: list[int] = [0] * self._capacity
        """The error window's signed errors, a ring of `_error_count` from `_error_next`."""
        self._error_next = 0
        self._error_count = 0
        self._sum_abs = 0
        self._sum_sq = 0
        self._sum_signed = 0
        self._delay_ns: int | None = None if initial_delay_ns is None else int(initial_delay_ns)
        self.frames_seen = 0
        self.adjustments: list[Adjustment] = []
        self._last: tuple[int, int, int, int] | None = None

    @property
    def last_stats(self) -> WindowStats | None:
        """Error statistics of the window judged at the last update."""
        return None if self._last is None else _stats(*self._last)

    @property
    def delay_ns(self) -> int | None:
        """The delay in force for the next trigger (None before any observation when no
        initial delay was given)."""
        return self._delay_ns

    def _mean_input(self, column: int) -> float:
        """Running average of one input over the last N frames; NaN before any."""
        n = len(self._inputs)
        return sum(row[column] for row in self._inputs) / n if n else float("nan")

    def mean_t5_ns(self) -> float:
        """Eq. 3: running average of the last N exposure durations."""
        return self._mean_input(4)

    def eq2_delay_ns(self) -> float:
        """Eq. 2 with the running averages of t_rotate, t1..t4 and t5 (Eq. 3)."""
        return eq2_delay_ns(
            self._mean_input(5),
            self._mean_input(0),
            self._mean_input(1),
            self._mean_input(2),
            self._mean_input(3),
            self._mean_input(4),
        )

    def window_stats(self) -> WindowStats:
        """Eq. 5, Eq. 6 and the signed mean over the current error window."""
        return _stats(self._error_count, self._sum_abs, self._sum_sq, self._sum_signed)

    def _clamp(self, delay_ns: float) -> int:
        """Round to ns and clamp to [0, t_rotate]: a negative sleep cannot be waited, and
        a sleep past t_rotate would aim at the next camera's sector."""
        upper = max(0, round(self._mean_input(5)))
        return min(max(0, round(delay_ns)), upper)

    def update(self, frame: FrameObservation) -> int:
        """Feed one frame's observation; return the delay (ns) for the next trigger."""
        return self.observe(
            frame.t1_ns,
            frame.t2_ns,
            frame.t3_ns,
            frame.t4_ns,
            frame.exposure_ns,
            frame.error_ns,
            frame.t_rotate_ns,
        )

    def observe(
        self,
        t1_ns: int,
        t2_ns: int,
        t3_ns: int,
        t4_ns: int,
        exposure_ns: int,
        error_ns: int,
        t_rotate_ns: int,
    ) -> int:
        """`update` for one frame's values as they are (the replay's per-frame call)."""
        row = (int(t1_ns), int(t2_ns), int(t3_ns), int(t4_ns), int(exposure_ns), int(t_rotate_ns))
        capacity = self._capacity
        if len(self._inputs) < capacity:
            self._inputs.append(row)
        else:
            self._inputs[self._next] = row
            self._next = (self._next + 1) % capacity
        error = int(error_ns)
        magnitude = abs(error)
        slot = self._error_next
        if self._error_count == capacity:
            old = self._errors[slot]
            old_magnitude = abs(old)
            self._sum_abs -= old_magnitude
            self._sum_sq -= old_magnitude * old_magnitude
            self._sum_signed -= old
        else:
            self._error_count += 1
        self._errors[slot] = error
        self._error_next = (slot + 1) % capacity
        self._sum_abs += magnitude
        self._sum_sq += magnitude * magnitude
        self._sum_signed += error
        index = self.frames_seen
        self.frames_seen += 1
        n = self._error_count
        self._last = (n, self._sum_abs, self._sum_sq, self._sum_signed)

        if self._delay_ns is None:
            # No configured delay: start from Eq. 2 (the method's initial t_sleep); the
            # error of this frame belongs to no delay of ours, so the window restarts.
            stats = _stats(*self._last)
            self._set_delay(index, self._clamp(self.eq2_delay_ns()), "initial", stats)
            return self._require_delay()

        config = self.config
        if n < config.min_frames:
            return self._delay_ns
        over_mean = eq5_mean_abs(self._sum_abs, n) > config.mean_error_threshold_ns
        over_var = eq6_variance(self._sum_abs, self._sum_sq, n) > config.variance_threshold_ns2
        if not (over_mean or over_var):
            return self._delay_ns
        stats = _stats(*self._last)
        reason: Literal["mean", "variance", "mean+variance"] = (
            "mean+variance" if over_mean and over_var else "mean" if over_mean else "variance"
        )
        if config.mode == "recompute":
            new_delay = self._clamp(self.eq2_delay_ns())
        else:
            new_delay = self._clamp(self._require_delay() - stats.signed_error_mean_ns)
        self._set_delay(index, new_delay, reason, stats)
        return new_delay

    def _set_delay(
        self,
        index: int,
        new_delay_ns: int,
        reason: Literal["mean", "variance", "mean+variance", "initial"],
        stats: WindowStats,
    ) -> None:
        old = self._delay_ns
        self._delay_ns = new_delay_ns
        self.adjustments.append(
            Adjustment(index, new_delay_ns if old is None else old, new_delay_ns, reason, stats)
        )
        self._error_next = 0
        self._error_count = 0
        self._sum_abs = 0
        self._sum_sq = 0
        self._sum_signed = 0

    def _require_delay(self) -> int:
        if self._delay_ns is None:  # pragma: no cover - set by the first update
            raise RuntimeError("controller has no delay yet")
        return self._delay_ns


def _stats(n: int, sum_abs: int, sum_sq: int, sum_signed: int) -> WindowStats:
    """Eq. 5, Eq. 6 and the signed mean of a window of n errors from its exact sums."""
    return WindowStats(
        frames=n,
        error_mean_ns=eq5_mean_abs(sum_abs, n),
        error_var_ns2=eq6_variance(sum_abs, sum_sq, n),
        signed_error_mean_ns=sum_signed / n if n else float("nan"),
    )
