"""Replay the self-adaptive controller over a recorded camera: what correction would do.

The error of a frame moves one-for-one with the trigger delay (the exposure lands later
by exactly the extra wait), so replaying the controller only needs each frame's
latencies, exposure, error and applied delay: error_if_corrected = error + (d_new - d_applied).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from syncaudit.analysis.controller import ControllerConfig, DelayController
from syncaudit.analysis.stamps import values_ns
from syncaudit.analysis.stats import error_mean, error_variance
from syncaudit.columns.table import Table


@dataclass(frozen=True, slots=True)
class ReplayResult:
    """Errors of the recorded frames had the controller been running."""

    adjustments: int
    final_delay_ns: int
    error_mean_ns: float
    error_var_ns2: float
    error_signed_mean_ns: float
    settled_error_mean_ns: float
    """Eq. 5 over the frames after the first adjustment took effect (the corrected state)."""
    settled_error_var_ns2: float
    """Eq. 6 over the same frames."""
    errors_ns: NDArray[np.float64]
    """Per paired frame, corrected signed error."""
    delays_ns: NDArray[np.int64]
    """Per paired frame, the delay the controller would have used."""
    frame_rows: NDArray[np.int64]
    """Per entry of `errors_ns`/`delays_ns`, its row position in the camera's frame table."""
    adjustment_rows: NDArray[np.int64]
    """Row position (frame table) of each frame after which the controller changed the delay."""
    adjustment_delays_ns: NDArray[np.int64]
    """The delay each adjustment set."""

    def per_frame(self, rows: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(corrected signed error, replayed delay) per row of the frame table, NaN elsewhere."""
        errors = np.full(rows, np.nan)
        delays = np.full(rows, np.nan)
        errors[self.frame_rows] = self.errors_ns
        delays[self.frame_rows] = self.delays_ns
        return errors, delays


def replay_controller(frames: Table, config: ControllerConfig) -> ReplayResult | None:
    """Run the controller over the paired frames of one camera (None without applied delays).

    `frames`: the camera's per-frame table (`CameraSync.table`).
    """
    paired = np.asarray(frames["paired"], dtype=bool)
    rows = frames.take(np.flatnonzero(paired))
    cols = [
        "t1_ns",
        "t2_ns",
        "t3_ns",
        "t4_ns",
        "exposure_duration_ns",
        "error_signed_ns",
        "applied_delay_ns",
        "t_estimated_ns",
    ]
    # Stamps (int64, MISSING where missing) as float64 with NaN, like the other columns.
    values = np.column_stack([_floats(rows, c) for c in cols]) if len(rows) else np.empty((0, 8))
    rotate = _floats(rows, "t_rotate_ns") + _floats(rows, "packet_phase_ns")
    ok = np.isfinite(values).all(axis=1) & np.isfinite(rotate)
    values, rotate = values[ok], rotate[ok]
    frame_rows = np.flatnonzero(paired)[ok].astype(np.int64)
    if not values.shape[0]:
        return None
    controller = DelayController(config, initial_delay_ns=int(values[0, 6]))
    error_list: list[float] = []
    delay_list: list[int] = []
    delay = int(values[0, 6])
    observe = controller.observe
    # Python floats and ints: the loop is per frame (the online algorithm), and numpy
    # scalars, per-frame objects and item assignment into arrays are slow.
    for (t1, t2, t3, t4, t5, err, applied, _), rot in zip(
        values.tolist(), rotate.tolist(), strict=True
    ):
        corrected = err + (delay - applied)
        error_list.append(corrected)
        delay_list.append(delay)
        delay = observe(
            round(t1), round(t2), round(t3), round(t4), round(t5), round(corrected), round(rot)
        )
    errors = np.array(error_list, dtype=np.float64)
    delays = np.array(delay_list, dtype=np.int64)
    abs_err = np.abs(errors)
    first = controller.adjustments[0].frame_index + 1 if controller.adjustments else 0
    settled = abs_err[first:]
    return ReplayResult(
        adjustments=len(controller.adjustments),
        final_delay_ns=delay,
        error_mean_ns=error_mean(abs_err),
        error_var_ns2=error_variance(abs_err),
        error_signed_mean_ns=float(errors.mean()) if errors.size else math.nan,
        settled_error_mean_ns=error_mean(settled),
        settled_error_var_ns2=error_variance(settled),
        errors_ns=errors,
        delays_ns=delays,
        frame_rows=frame_rows,
        adjustment_rows=frame_rows[
            np.array([a.frame_index for a in controller.adjustments], dtype=np.int64)
        ],
        adjustment_delays_ns=np.array(
            [a.new_delay_ns for a in controller.adjustments], dtype=np.int64
        ),
    )


def _floats(rows: Table, name: str) -> NDArray[np.float64]:
    """A column as float64: int64 stamps with NaN where missing, floats as they are."""
    column = rows[name]
    if column.dtype == np.int64:
        return values_ns(rows, name)
    return np.asarray(column, dtype=np.float64)
