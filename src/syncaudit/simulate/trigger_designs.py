"""Simulated trigger designs other than the method's chain, with exact truth.

`SyncSimConfig.trigger_design` picks one (docs/trigger-designs.md):

- `ptp_phase`: every camera fires at `k / frame_rate + phase` of PTP time (the host's
  system time, as TIER IV sensor_trigger reads it), and publishes the bare trigger time
  (`builtin_interfaces/Time`); the exposure starts t4 after the trigger.
- `lidar_sync_output`: the LiDAR emits a pulse as it crosses `sync_output_angle_deg`; the
  camera fires its configured delay after it (bare trigger times).
- `free_running`: the camera exposes on its own clock (`frame_rate`, off by `clock_ppm`),
  no trigger records.

`lidar_phase_lock_deg` phase-locks the LiDAR (no rate drift; it crosses that azimuth at the
top of every PTP second); `lock_slip_*` makes it lose the lock for a while. A camera named
in `readout_us` has a rolling shutter of that readout over `rows` rows: the exposure start
written is the top row's, and the rig's target row (the centre) is what the ideal timing
aims at. Every camera's `delay_error_us` is the timing error put in: the phase, the delay
after the pulse or the clock's phase are set that far later than the ideal.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from syncaudit.config import ConfigModel

NS_PER_S = 1_000_000_000
SimDesign = Literal["ptp_phase", "lidar_sync_output", "free_running"]


class TriggerDesignSim(ConfigModel):
    """How the simulated cameras are triggered when not by the method's chain."""

    design: SimDesign
    frame_rate_hz: int = Field(default=10, ge=1, le=1000)
    """ptp_phase and free_running: frames per second (dividing 1 s into whole ns)."""
    lidar_phase_lock_deg: float | None = Field(default=None, ge=0.0, lt=360.0)
    """Phase-lock the LiDAR: it crosses this packet azimuth at the top of each second."""
    lock_slip_start_s: float | None = Field(default=None, ge=0.0)
    """A phase-locked LiDAR slips out of lock from this log time ..."""
    lock_slip_length_s: float = Field(default=1.0, gt=0.0)
    lock_slip_deg: float = Field(default=4.0, ge=-30.0, le=30.0)
    """... by up to this rotation, and back."""
    sync_output_angle_deg: float | None = Field(default=None, ge=0.0, lt=360.0)
    """lidar_sync_output: pulse azimuth (None: the zero azimuth)."""
    trigger_jitter_us: float = Field(default=2.0, ge=0.0, le=1_000.0)
    """Std of the trigger (or frame clock) jitter."""
    clock_ppm: float = Field(default=0.0, ge=-1_000.0, le=1_000.0)
    """free_running: the camera clock's rate error."""
    readout_us: dict[str, float] = Field(default_factory=dict)
    """Rolling-shutter cameras by name: top row's start to the bottom row's (rows x row time)."""
    rows: int = Field(default=2160, ge=2, le=100_000)


class RotationLike(Protocol):
    """What the simulator needs of a rotation model."""

    @property
    def w0_deg_ns(self) -> float: ...

    def angle_deg(self, t_ns: NDArray[np.float64]) -> NDArray[np.float64]: ...

    def rate_deg_ns(self, t_ns: NDArray[np.float64]) -> NDArray[np.float64]: ...

    def time_at_ns(self, angle_deg: NDArray[np.float64]) -> NDArray[np.float64]: ...


@dataclass(frozen=True, slots=True)
class SlippingRotation:
    """A rotation that runs ahead of `base` by slip_deg * sin^2 over a window, then returns."""

    base: RotationLike
    start_ns: float
    length_ns: float
    slip_deg: float

    @property
    def w0_deg_ns(self) -> float:
        """Nominal rate (the base's)."""
        return self.base.w0_deg_ns

    def _phase(self, t_ns: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.clip((np.asarray(t_ns, np.float64) - self.start_ns) / self.length_ns, 0.0, 1.0)

    def angle_deg(self, t_ns: NDArray[np.float64]) -> NDArray[np.float64]:
        """Unwrapped azimuth (deg) at t."""
        return self.base.angle_deg(t_ns) + self.slip_deg * np.sin(np.pi * self._phase(t_ns)) ** 2

    def rate_deg_ns(self, t_ns: NDArray[np.float64]) -> NDArray[np.float64]:
        """Angular velocity (deg/ns) at t."""
        x = self._phase(t_ns)
        inside = (x > 0.0) & (x < 1.0)
        bump = self.slip_deg * np.pi / self.length_ns * np.sin(2.0 * np.pi * x)
        return self.base.rate_deg_ns(t_ns) + np.where(inside, bump, 0.0)

    def time_at_ns(self, angle_deg: NDArray[np.float64]) -> NDArray[np.float64]:
        """Solve A(t) = angle (Newton from the base's solution; A is strictly increasing)."""
        target = np.asarray(angle_deg, dtype=np.float64)
        return newton_time_ns(self, target, self.base.time_at_ns(target))


def newton_time_ns(
    rotation: RotationLike, target_deg: NDArray[np.float64], start_ns: NDArray[np.float64]
) -> NDArray[np.float64]:
    """The times the rotation reaches `target_deg`, by Newton from `start_ns` (the angle is
    strictly increasing; steps below 1e-4 ns stop it, 50 at most)."""
    t = start_ns
    for _ in range(50):
        step = (rotation.angle_deg(t) - target_deg) / rotation.rate_deg_ns(t)
        t = t - step
        if float(np.max(np.abs(step), initial=0.0)) < 1e-4:
            break
    return t


def locked_start_deg(lock_deg: float, w0_deg_ns: float, start_sensor_ns: int) -> float:
    """Azimuth at the log start of a LiDAR that crosses `lock_deg` at each top of second."""
    to_tos = (-start_sensor_ns) % NS_PER_S
    return (lock_deg - w0_deg_ns * to_tos) % 360.0


@dataclass(frozen=True, slots=True)
class DesignTimes:
    """One camera's frames under a design (true time, ns)."""

    trigger_ns: NDArray[np.int64] | None
    """When the trigger fired (None: free-running, no trigger records)."""
    exposure_start_ns: NDArray[np.int64]
    """Top row's exposure start."""
    target_row_offset_ns: int
    """How much later the rig's target row (centre) exposes than the top row."""
    row_time_ns: float
    setting: dict[str, float]
    """The design's setting used, and its ideal (truth)."""


def row_time_ns(design: TriggerDesignSim, camera: str) -> float:
    """The camera's row time (0: global shutter)."""
    readout = design.readout_us.get(camera)
    return 0.0 if readout is None else readout * 1e3 / design.rows


def _ideal_phase_ns(ideal_sensor_ns: NDArray[np.float64], period_ns: int) -> float:
    """Circular mean of the ideal trigger times' place in the frame interval."""
    angle = (ideal_sensor_ns % period_ns) / period_ns * 2.0 * math.pi
    mean = math.atan2(float(np.sin(angle).mean()), float(np.cos(angle).mean()))
    return (mean % (2.0 * math.pi)) / (2.0 * math.pi) * period_ns


def design_times(
    design: TriggerDesignSim,
    camera: str,
    *,
    t_est_ns: NDArray[np.int64],
    t4_ns: NDArray[np.int64],
    t5_ns: NDArray[np.int64],
    pulse_true_ns: Callable[[], NDArray[np.int64]],
    delay_error_ns: int,
    rng: np.random.Generator,
) -> DesignTimes:
    """Trigger and exposure start of every frame of one camera under `design`.

    The ideal setting puts the target row's mid-exposure on t_est on average; the setting
    used is `delay_error_ns` later. `pulse_true_ns` gives the sync output's pulse per frame.
    """
    n = t_est_ns.size
    row_time = row_time_ns(design, camera)
    target_offset = round(row_time * (design.rows // 2))
    jitter = np.rint(rng.normal(0.0, design.trigger_jitter_us * 1e3, n)).astype(np.int64)
    # Exposure start (top row) that would put the target row's middle on t_est:
    ideal_start = t_est_ns - t5_ns // 2 - target_offset
    period = NS_PER_S // design.frame_rate_hz
    if design.design == "ptp_phase":
        # sensor_trigger runs on the host's system time (PTP time where PTP runs).
        ideal = (ideal_start - t4_ns).astype(np.float64)
        phase = _ideal_phase_ns(ideal, period)
        k = np.rint((ideal - phase) / period).astype(np.int64)
        used = round(phase) + delay_error_ns
        trigger = k * period + used + jitter
        setting = {"phase_ns": float(used), "ideal_phase_ns": phase, "period_ns": float(period)}
        return DesignTimes(trigger, trigger + t4_ns, target_offset, row_time, setting)
    if design.design == "lidar_sync_output":
        pulse = pulse_true_ns()
        ideal_delay = float(np.mean(ideal_start - t4_ns - pulse))
        used = round(ideal_delay) + delay_error_ns
        trigger = pulse + used + jitter
        setting = {"delay_ns": float(used), "ideal_delay_ns": ideal_delay}
        return DesignTimes(trigger, trigger + t4_ns, target_offset, row_time, setting)
    step = period * (1.0 + design.clock_ppm * 1e-6)
    ticks = np.arange(n, dtype=np.float64) * step
    ideal_t0 = float(np.mean(ideal_start - ticks))
    used = round(ideal_t0) + delay_error_ns
    start = used + np.rint(ticks).astype(np.int64) + jitter
    setting = {"t0_ns": float(used), "ideal_t0_ns": ideal_t0, "period_ns": step}
    return DesignTimes(None, start, target_offset, row_time, setting)
