"""Trigger designs: which one a camera's records show, and the correction in its own units.

Four designs (docs/trigger-designs.md): `lidar_packet` (the method's chain, TriggerEvents
with checkpoints), `ptp_phase` (bare trigger times at `n / frame_rate + phase` of PTP time,
TIER IV sensor_trigger), `lidar_sync_output` (bare trigger times at a fixed point of each
LiDAR revolution) and `free_running` (no trigger records). Every correction is a shift of
the exposure by `shift_ns` (the error moves one-for-one with it), proven by replay: the
shift is applied to the recorded frames' errors and Eq. 5/6 recomputed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from syncaudit.analysis.stats import error_mean, error_variance

NS_PER_S = 1_000_000_000
FULL_TURN_DEG = 360.0
SENSOR_TRIGGER_PHASE_STEP_DEG = 0.1
"""sensor_trigger reads `phase` as int64(phase * 10) / 3600 of the frame interval: 0.1 deg."""
LOCK_PARAMETER = {
    "velodyne": ("phase_lock_offset", "deg", 1.0),
    "hesai": ("sync_angle", "deg", 1.0),
    "ouster": ("phase_lock_offset", "millideg", 1000.0),
}
"""The LiDAR's own name for the azimuth it crosses at the top of each second, its unit and
degrees-to-unit factor (Velodyne web UI Phase Lock offset, Hesai sync angle, Ouster
`phase_lock_offset` in millidegrees)."""
CLEAR_RATIO = 0.5
"""One explanation of the trigger times is chosen when its residual is under half the other's."""


@dataclass(frozen=True, slots=True)
class DesignGuess:
    """The design a camera's records look like, why, and what was measured on the way."""

    design: str
    why: str
    frame_period_ns: float
    phase_deg: float | None = None
    """ptp_phase: the trigger phase within the frame interval after the top of second."""
    tos_residual_ns: float = math.nan
    """Std of the trigger times about a fixed phase of PTP time."""
    lidar_residual_ns: float = math.nan
    """Std of the trigger times about a fixed point of the LiDAR revolution."""
    lidar_lag_ns: float = math.nan
    """Mean time from the revolution's zero crossing to the trigger (sync output)."""

    def to_dict(self) -> dict[str, Any]:
        """JSON form (microseconds)."""
        return {
            "design": self.design,
            "why": self.why,
            "frame_period_us": _us(self.frame_period_ns),
            "phase_deg": self.phase_deg,
            "tos_residual_us": _us(self.tos_residual_ns),
            "lidar_residual_us": _us(self.lidar_residual_ns),
            "lidar_lag_us": _us(self.lidar_lag_ns),
        }


def _us(ns: float) -> float | None:
    return round(ns / 1e3, 3) if math.isfinite(ns) else None


def frame_period_ns(times_ns: NDArray[np.int64]) -> float:
    """The frame interval: 1 s over the nearest whole frame rate, else the median step."""
    steps = np.diff(np.sort(times_ns)).astype(np.float64)
    steps = steps[steps > 0]
    if not steps.size:
        return math.nan
    median = float(np.median(steps))
    rate = round(NS_PER_S / median)
    if rate >= 1 and abs(NS_PER_S / rate - median) < 0.01 * median:
        return float(NS_PER_S // rate)
    return median


def phase_in_period_ns(times_ns: NDArray[np.int64], period_ns: float) -> tuple[float, float]:
    """Circular mean and std of each time's place in its frame interval after the top of
    second (sensor_trigger restarts its grid at every second)."""
    within = (times_ns % NS_PER_S).astype(np.float64) % period_ns
    angle = within / period_ns * 2.0 * math.pi
    c, s = float(np.cos(angle).mean()), float(np.sin(angle).mean())
    mean = (math.atan2(s, c) % (2.0 * math.pi)) / (2.0 * math.pi) * period_ns
    wrapped = (within - mean + period_ns / 2.0) % period_ns - period_ns / 2.0
    return mean, float(wrapped.std())


def lag_after_zero_ns(
    times_ns: NDArray[np.int64], zero_ns: NDArray[np.int64]
) -> NDArray[np.float64]:
    """Each time less the last zero crossing before it (NaN before the first)."""
    zero = np.sort(zero_ns)
    at = np.searchsorted(zero, times_ns, side="right") - 1
    ok = at >= 0
    out = np.full(times_ns.shape, np.nan)
    out[ok] = (times_ns[ok] - zero[at[ok]]).astype(np.float64)
    return out


def guess_design(
    *,
    trigger_ns: NDArray[np.int64],
    has_checkpoints: bool,
    frame_ns: NDArray[np.int64],
    zero_host_ns: NDArray[np.int64],
    stated: str | None = None,
) -> DesignGuess:
    """The design of one camera from its trigger records (or its exposure starts).

    `trigger_ns` are bare trigger times (host clock), `has_checkpoints` whether the records
    carry the LiDAR packet checkpoint (TriggerEvent), `frame_ns` the exposure starts,
    `zero_host_ns` the LiDAR's zero crossings on the host clock. `stated` is the rig's.
    """
    times = trigger_ns if trigger_ns.size >= 3 else frame_ns
    period = frame_period_ns(times) if times.size >= 3 else math.nan
    if not math.isfinite(period):
        return DesignGuess(stated or "free_running", "too few frames to tell", period)
    phase_ns, tos_std = phase_in_period_ns(times, period)
    lag = lag_after_zero_ns(times, zero_host_ns)
    lag = lag[np.isfinite(lag)]
    lidar_std = float(lag.std()) if lag.size >= 3 else math.nan
    lag_mean = float(lag.mean()) if lag.size else math.nan
    phase_deg = phase_ns / period * FULL_TURN_DEG
    base = DesignGuess("", "", period, phase_deg, tos_std, lidar_std, lag_mean)
    measured = (
        f"times hold a phase of PTP time to {tos_std / 1e3:.1f} us (std) and a point of the "
        f"LiDAR revolution to {lidar_std / 1e3:.1f} us"
    )
    if stated is not None:
        return _with(base, stated, f"stated by the rig (trigger.design); {measured}")
    if has_checkpoints:
        return _with(base, "lidar_packet", "trigger records carry the LiDAR packet checkpoint")
    if trigger_ns.size < 3:
        return _with(base, "free_running", f"no trigger records; exposure start {measured}")
    if math.isfinite(lidar_std) and lidar_std < CLEAR_RATIO * tos_std:
        return _with(base, "lidar_sync_output", f"bare trigger times; {measured}")
    if not math.isfinite(lidar_std) or tos_std < CLEAR_RATIO * lidar_std:
        return _with(base, "ptp_phase", f"bare trigger times; {measured}")
    return _with(
        base,
        "ptp_phase",
        f"bare trigger times; {measured}: the LiDAR is phase-locked, so a PTP phase trigger "
        "and its sync output look alike (state trigger.design in the rig)",
    )


def _with(guess: DesignGuess, design: str, why: str) -> DesignGuess:
    return DesignGuess(
        design,
        why,
        guess.frame_period_ns,
        guess.phase_deg,
        guess.tos_residual_ns,
        guess.lidar_residual_ns,
        guess.lidar_lag_ns,
    )


@dataclass(frozen=True, slots=True)
class Replay:
    """Eq. 5/6 of the recorded frames before and after a constant shift."""

    shift_ns: float
    current_mean_ns: float
    current_var_ns2: float
    expected_mean_ns: float
    expected_var_ns2: float
    floor_ns: float
    """Eq. 5 no constant shift can go below: the mean |error| about its own median."""


def replay_shift(errors_ns: NDArray[np.float64]) -> Replay:
    """The shift that centres the signed errors, applied to them (Eq. 5/6 recomputed).

    The median, not the mean, centres them: Eq. 5 (mean |e|) is least there.
    """
    e = errors_ns[np.isfinite(errors_ns)]
    if not e.size:
        nan = math.nan
        return Replay(nan, nan, nan, nan, nan, nan)
    shift = -float(np.median(e))
    after = np.abs(e + shift)
    return Replay(
        shift,
        error_mean(np.abs(e)),
        error_variance(np.abs(e)),
        error_mean(after),
        error_variance(after),
        error_mean(after),
    )


def _wrap_deg(value: float) -> float:
    return value % FULL_TURN_DEG


def design_setting(
    guess: DesignGuess,
    shift_ns: float,
    *,
    omega_deg_s: float,
    sync_output_angle_deg: float | None,
    applied_delay_ns: float = math.nan,
) -> dict[str, Any] | None:
    """What to set for a shift of the exposure by `shift_ns`, in the design's own units
    (`applied_delay_ns`: the chain's recorded t_sleep, for `lidar_packet`)."""
    if not math.isfinite(shift_ns):
        return None
    if guess.design == "lidar_packet":
        if not math.isfinite(applied_delay_ns):
            return None
        return {
            "parameter": "t_sleep",
            "value": round((applied_delay_ns + shift_ns) / 1e3, 3),
            "unit": "us",
            "current_value": round(applied_delay_ns / 1e3, 3),
        }
    if guess.design == "ptp_phase" and guess.phase_deg is not None:
        exact = _wrap_deg(guess.phase_deg + shift_ns / guess.frame_period_ns * FULL_TURN_DEG)
        step = SENSOR_TRIGGER_PHASE_STEP_DEG
        value = round(round(exact / step) * step, 1) % FULL_TURN_DEG
        return {
            "parameter": "phase",
            "value": value,
            "unit": "deg",
            "exact_value": round(exact, 4),
            "current_value": round(guess.phase_deg, 4),
            "step": step,
            "quantisation_us": round(
                ((value - exact + 180.0) % 360.0 - 180.0) / 360.0 * guess.frame_period_ns / 1e3,
                3,
            ),
            "also_us": round(exact / 360.0 * guess.frame_period_ns / 1e3, 3),
        }
    if guess.design == "lidar_sync_output" and sync_output_angle_deg is not None:
        return {
            "parameter": "sync_pulse_out_angle",
            "value": round(_wrap_deg(sync_output_angle_deg + omega_deg_s * shift_ns / 1e9), 3),
            "unit": "deg",
            "current_value": sync_output_angle_deg,
        }
    if guess.design == "lidar_sync_output":
        return {
            "parameter": "trigger_delay",
            "value": round(shift_ns / 1e3, 3),
            "unit": "us",
            "meaning": "add to the camera's trigger delay after the pulse",
            "pulse_angle_change_deg": round(omega_deg_s * shift_ns / 1e9, 4),
        }
    if guess.design == "free_running":
        return {
            "parameter": "frame_phase_offset",
            "value": round(shift_ns / 1e3, 3),
            "unit": "us",
            "meaning": "move the camera clock's frame start by this much",
        }
    return None


def lock_setting(
    vendor: str | None, lock_azimuth_deg: float, common_error_ns: float, omega_deg_s: float
) -> dict[str, Any]:
    """Move the LiDAR's lock angle so that it meets every camera `common_error_ns` later.

    A LiDAR crossing azimuth L at the top of second crosses L - d at it when locked to
    L - d, i.e. it reaches every azimuth d / omega later.
    """
    name, unit, factor = LOCK_PARAMETER.get(vendor or "", ("phase_lock_offset", "deg", 1.0))
    new_deg = _wrap_deg(lock_azimuth_deg - omega_deg_s * common_error_ns / 1e9)
    return {
        "parameter": name,
        "value": round(new_deg * factor, 3),
        "unit": unit,
        "current_value": round(lock_azimuth_deg * factor, 3),
    }


def recommendation(
    guess: DesignGuess,
    replay: Replay,
    setting: dict[str, Any] | None,
    *,
    threshold_ns: float,
    why_extra: str = "",
) -> dict[str, Any]:
    """The advice object ({"action", "shift_us", ... "set"}) of one camera."""
    worth = math.isfinite(replay.current_mean_ns) and (
        replay.current_mean_ns > threshold_ns
        and replay.current_mean_ns - replay.expected_mean_ns > 0.1 * threshold_ns
    )
    floor_bound = math.isfinite(replay.floor_ns) and replay.floor_ns > threshold_ns
    action = "shift_trigger" if worth else "none"
    if floor_bound:
        action = "per_frame_compensation"
    why = (
        f"{guess.design}: shifting the exposure by {replay.shift_ns / 1e3:+.1f} us brings "
        f"Eq. 5 from {replay.current_mean_ns / 1e3:.1f} to {replay.expected_mean_ns / 1e3:.1f} us "
        "(replayed on the recorded frames)"
        if worth
        else f"{guess.design}: the mean error is within the threshold"
    )
    if floor_bound:
        why = (
            f"{guess.design}: the error scatters {replay.floor_ns / 1e3:.1f} us about its "
            "centre, above the threshold, which no constant shift removes"
            + (
                ": the method's per-frame t_sleep (Eq. 2) follows it"
                if guess.design == "lidar_packet"
                else ""
            )
        )
    if why_extra:
        why = f"{why}; {why_extra}"
    return {
        "action": action,
        "shift_us": _us(replay.shift_ns),
        "expected_error_mean_us": _us(replay.expected_mean_ns),
        "expected_error_var_us2": _var(replay.expected_var_ns2),
        "current_error_mean_us": _us(replay.current_mean_ns),
        "floor_us": _us(replay.floor_ns),
        "why": why,
        "set": setting if action != "none" else None,
    }


def _var(ns2: float) -> float | None:
    return round(ns2 / 1e6, 3) if math.isfinite(ns2) else None
