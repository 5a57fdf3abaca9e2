"""The self-adaptive delay controller: Eq. 3/5/6 against numpy, thresholds, convergence."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from syncaudit.analysis.controller import (
    ControllerConfig,
    DelayController,
    FrameObservation,
    eq2_delay_ns,
    eq6_variance,
)

T_ROTATE_NS = 33_333_333  # 120 deg at 600 RPM
LATENCIES_NS = (300_000, 50_000, 120_000, 40_000)


def _frame(
    error_ns: int, exposure_ns: int = 2_000_000, t_rotate_ns: int = T_ROTATE_NS
) -> FrameObservation:
    t1, t2, t3, t4 = LATENCIES_NS
    return FrameObservation(t1, t2, t3, t4, exposure_ns, error_ns, t_rotate_ns)


class Plant:
    """A camera whose frame lands at zero crossing + delay + t1..t4 + t5/2, with jitter."""

    def __init__(self, seed: int, jitter_ns: float, bias_ns: int = 0) -> None:
        self.rng = np.random.default_rng(seed)
        self.jitter_ns = jitter_ns
        self.bias_ns = bias_ns
        """Latency the driver does not measure (so only 'shift' can remove it)."""

    def frame(self, delay_ns: int, exposure_ns: int) -> FrameObservation:
        t1, t2, t3, t4 = (int(v + self.rng.normal(0.0, self.jitter_ns)) for v in LATENCIES_NS)
        t_l = delay_ns + t1 + t2 + t3 + t4 + self.bias_ns + exposure_ns // 2
        return FrameObservation(t1, t2, t3, t4, exposure_ns, t_l - T_ROTATE_NS, T_ROTATE_NS)


def test_equations_against_numpy() -> None:
    config = ControllerConfig(
        window_frames=7, min_frames=7, mean_error_threshold_ns=10**12, variance_threshold_ns2=1e30
    )
    controller = DelayController(config, initial_delay_ns=1_000_000)
    rng = np.random.default_rng(11)
    exposures = rng.integers(1_000_000, 12_000_000, size=30)
    errors = rng.integers(-3_000_000, 3_000_000, size=30)
    rotates = rng.integers(33_000_000, 33_600_000, size=30)
    for i in range(30):
        controller.update(_frame(int(errors[i]), int(exposures[i]), int(rotates[i])))
        lo = max(0, i - 6)
        # Eq. 3
        assert controller.mean_t5_ns() == pytest.approx(exposures[lo : i + 1].mean(), rel=1e-12)
        stats = controller.window_stats()
        abs_err = np.abs(errors[lo : i + 1]).astype(np.float64)
        n = abs_err.size
        assert stats.frames == n
        # Eq. 5
        assert stats.error_mean_ns == pytest.approx(abs_err.mean(), rel=1e-12)
        # Eq. 6 literally, and as numpy's unbiased variance
        if n >= 2:
            literal = (np.sum(abs_err**2) / n - abs_err.mean() ** 2) * n / (n - 1)
            assert stats.error_var_ns2 == pytest.approx(literal, rel=1e-9)
            assert stats.error_var_ns2 == pytest.approx(np.var(abs_err, ddof=1), rel=1e-9)
        assert stats.signed_error_mean_ns == pytest.approx(errors[lo : i + 1].mean(), rel=1e-12)
        # Eq. 2 from running averages
        expected = rotates[lo : i + 1].mean() - (
            sum(LATENCIES_NS) + exposures[lo : i + 1].mean() / 2
        )
        assert controller.eq2_delay_ns() == pytest.approx(expected, rel=1e-12)
    assert controller.adjustments == []


def test_eq6_exact_for_constant_errors() -> None:
    assert eq6_variance(5 * 123_456, 5 * 123_456**2, 5) == 0.0
    assert np.isnan(eq6_variance(7, 49, 1))
    assert eq2_delay_ns(100.0, 1.0, 2.0, 3.0, 4.0, 10.0) == 85.0


def test_no_action_below_thresholds() -> None:
    config = ControllerConfig(window_frames=10, min_frames=10)
    controller = DelayController(config, initial_delay_ns=30_000_000)
    rng = np.random.default_rng(5)
    for error in rng.integers(-200_000, 200_000, size=200):
        assert controller.update(_frame(int(error))) == 30_000_000
    assert controller.adjustments == []
    assert controller.last_stats is not None
    assert controller.last_stats.error_mean_ns < config.mean_error_threshold_ns


def test_no_action_before_min_frames() -> None:
    config = ControllerConfig(window_frames=10, min_frames=6)
    controller = DelayController(config, initial_delay_ns=10_000_000)
    for _ in range(5):
        assert controller.update(_frame(5_000_000)) == 10_000_000
    assert controller.update(_frame(5_000_000)) != 10_000_000
    assert controller.adjustments[0].frame_index == 5
    assert controller.adjustments[0].reason == "mean"


@pytest.mark.parametrize("mode", ["recompute", "shift"])
def test_converges_from_wrong_delay(mode: str) -> None:
    config = ControllerConfig(mode=mode)  # type: ignore[arg-type]
    ideal_ns = round(eq2_delay_ns(T_ROTATE_NS, *LATENCIES_NS, 2_000_000))
    controller = DelayController(config, initial_delay_ns=ideal_ns + 3_000_000)
    plant = Plant(seed=1, jitter_ns=10_000.0)
    delay = controller.delay_ns
    assert delay is not None
    errors = []
    for _ in range(60):
        frame = plant.frame(delay, 2_000_000)
        errors.append(frame.error_ns)
        delay = controller.update(frame)
    first = np.abs(errors[:10]).mean()
    last = np.abs(errors[-config.window_frames :]).mean()
    assert first > 2_900_000
    assert last < config.mean_error_threshold_ns
    # One adjustment after the first full window, then nothing (no hunting).
    assert len(controller.adjustments) == 1
    assert controller.adjustments[0].frame_index == config.window_frames - 1
    assert abs(delay - ideal_ns) < 20_000


def test_shift_removes_unmeasured_bias_recompute_cannot() -> None:
    bias_ns = 1_500_000
    for mode, should_converge in (("shift", True), ("recompute", False)):
        config = ControllerConfig(mode=mode)  # type: ignore[arg-type]
        ideal_ns = round(eq2_delay_ns(T_ROTATE_NS, *LATENCIES_NS, 2_000_000))
        controller = DelayController(config, initial_delay_ns=ideal_ns)
        plant = Plant(seed=2, jitter_ns=5_000.0, bias_ns=bias_ns)
        delay = ideal_ns
        errors = []
        for _ in range(50):
            frame = plant.frame(delay, 2_000_000)
            errors.append(frame.error_ns)
            delay = controller.update(frame)
        converged = bool(np.abs(errors[-10:]).mean() < config.mean_error_threshold_ns)
        assert converged is should_converge, mode


def test_recompute_follows_the_light() -> None:
    """A tunnel (2 ms -> 12 ms exposure) moves the mid-exposure; Eq. 3 brings it back."""
    config = ControllerConfig(window_frames=10, min_frames=10, mean_error_threshold_ns=1_000_000)
    ideal_bright = round(eq2_delay_ns(T_ROTATE_NS, *LATENCIES_NS, 2_000_000))
    controller = DelayController(config, initial_delay_ns=ideal_bright)
    plant = Plant(seed=4, jitter_ns=5_000.0)
    delay = ideal_bright
    errors = []
    for i in range(80):
        exposure = 2_000_000 if i < 20 else 12_000_000
        frame = plant.frame(delay, exposure)
        errors.append(frame.error_ns)
        delay = controller.update(frame)
    assert abs(errors[20]) > 4_900_000  # half of the 10 ms longer exposure
    assert all(a.reason != "initial" for a in controller.adjustments)
    assert np.abs(errors[-10:]).mean() < 100_000
    assert delay == pytest.approx(ideal_bright - 5_000_000, abs=20_000)


def test_initial_delay_from_eq2_and_clamp() -> None:
    controller = DelayController(ControllerConfig())
    assert controller.delay_ns is None
    first = controller.update(_frame(0))
    assert first == round(eq2_delay_ns(T_ROTATE_NS, *LATENCIES_NS, 2_000_000))
    assert controller.adjustments[0].reason == "initial"
    # A camera almost at the zero crossing: Eq. 2 is negative, the delay clamps to 0.
    near = DelayController(ControllerConfig())
    assert near.update(_frame(0, t_rotate_ns=100_000)) == 0
    # Shifting past t_rotate clamps to t_rotate.
    late = DelayController(ControllerConfig(mode="shift", window_frames=2, min_frames=2), 1_000)
    for _ in range(2):
        delay = late.update(_frame(-10 * T_ROTATE_NS))
    assert delay == T_ROTATE_NS


def test_config_validation() -> None:
    with pytest.raises(ValidationError):
        ControllerConfig(window_frames=1)
    with pytest.raises(ValidationError):
        ControllerConfig(window_frames=5, min_frames=6)
    with pytest.raises(ValidationError):
        ControllerConfig(mode="guess")  # type: ignore[arg-type]
