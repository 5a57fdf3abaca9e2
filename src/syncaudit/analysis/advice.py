"""Advice per camera, proven by replay on the log itself: what to change and what it buys.

Every candidate is replayed over the recorded frames (a frame's error moves one-for-one
with its delay): the log as recorded, one constant shift of the trigger (by minus the
median signed error, the shift that minimises Eq. 5), the seed's self-adaptive controller
(`analysis.replay`) and ours (`analysis.feedforward`, parameters fitted to the log). The
recommendation is the action that replays best, the simpler one when the other gains
less than a margin, and `none` when the recorded Eq. 5 is within that margin of the
camera's floor (`analysis.floor`, what its trigger design can reach) or nothing gains it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import NDArray

from syncaudit.analysis.feedforward import FeedForwardReplay, best_feedforward
from syncaudit.analysis.floor import ErrorFloor, error_floor
from syncaudit.analysis.stats import error_mean, error_variance
from syncaudit.columns.table import Table
from syncaudit.units import finite_or_none, ns_to_us

if TYPE_CHECKING:
    from syncaudit.analysis.replay import ReplayResult

__all__ = ["Advice", "WhatIf", "advise_camera"]

Action = Literal["shift_trigger", "per_frame_compensation", "none"]

MARGIN_MIN_NS = 10_000.0
"""An action must lower Eq. 5 by at least 10 us ..."""
MARGIN_FRACTION = 0.05
"""... and by 5 % of the recorded Eq. 5 to be worth recommending (or worth preferring
over a simpler one): less is within what the log's own sampling moves."""

AS_RECORDED = "as recorded"
CONSTANT_SHIFT = "constant shift"
SEED_CONTROLLER = "seed controller (Eq. 2, running average)"
FEEDFORWARD = "feed-forward + dead band (ours)"


@dataclass(frozen=True, slots=True)
class WhatIf:
    """Eq. 5/6 of the recorded frames under one policy."""

    policy: str
    error_mean_ns: float
    error_var_ns2: float
    adjustments: int

    def to_dict(self) -> dict[str, Any]:
        """JSON form (microseconds)."""
        return {
            "policy": self.policy,
            "error_mean_us": ns_to_us(self.error_mean_ns),
            "error_var_us2": finite_or_none(self.error_var_ns2 / 1e6),
            "adjustments": self.adjustments,
        }


@dataclass(frozen=True, slots=True)
class Advice:
    """One camera's recommendation, the replays behind it and its floor."""

    action: Action
    shift_ns: float | None
    expected_mean_ns: float
    expected_var_ns2: float
    current_mean_ns: float
    floor: ErrorFloor
    why: str
    what_if: list[WhatIf]
    advised_delay_ns: NDArray[np.float64]
    """Per row of the camera's frame table, the delay the recommended action would have
    used (NaN where the frame is not paired or no delay was recorded)."""
    feedforward: FeedForwardReplay | None

    @property
    def at_floor(self) -> bool:
        """No action lowers Eq. 5 by the margin: a correction cannot change the verdict."""
        return self.action == "none"

    def recommendation(self) -> dict[str, Any]:
        """The `recommendation` JSON object."""
        return {
            "action": self.action,
            "shift_us": None if self.shift_ns is None else ns_to_us(self.shift_ns),
            "expected_error_mean_us": ns_to_us(self.expected_mean_ns),
            "expected_error_var_us2": finite_or_none(self.expected_var_ns2 / 1e6),
            "current_error_mean_us": ns_to_us(self.current_mean_ns),
            "floor_us": ns_to_us(self.floor.error_mean_ns),
            "why": self.why,
        }

    def to_dict(self) -> dict[str, Any]:
        """The camera's `recommendation`, `what_if`, `floor` and `controller` JSON fields."""
        return {
            "recommendation": self.recommendation(),
            "what_if": [w.to_dict() for w in self.what_if],
            "floor": self.floor.to_dict(),
            "controller": None if self.feedforward is None else self.feedforward.config.to_dict(),
        }


def _floats(frames: Table, name: str) -> NDArray[np.float64]:
    from syncaudit.analysis.stamps import values_ns

    column = frames[name]
    if column.dtype == np.int64:
        return values_ns(frames, name)
    return np.asarray(column, dtype=np.float64)


def _stats(errors_ns: NDArray[np.float64]) -> tuple[float, float]:
    magnitude = np.abs(errors_ns)
    return error_mean(magnitude), error_variance(magnitude)


def _margin_ns(current_ns: float) -> float:
    return max(MARGIN_MIN_NS, MARGIN_FRACTION * current_ns) if math.isfinite(current_ns) else 0.0


def advise_camera(frames: Table, seed: ReplayResult | None) -> Advice:
    """Replay every policy over one camera's frame table and pick the recommendation."""
    rows = np.flatnonzero(np.asarray(frames["paired"], dtype=bool))
    error = _floats(frames, "error_signed_ns")[rows]
    exposure = _floats(frames, "exposure_duration_ns")[rows]
    applied = _floats(frames, "applied_delay_ns")[rows]
    ok = np.isfinite(error) & np.isfinite(exposure)
    rows, error, exposure, applied = rows[ok], error[ok], exposure[ok], applied[ok]
    chain = np.sum([_floats(frames, f"t{k}_ns")[rows] for k in range(1, 5)], axis=0)
    floor = error_floor(error, exposure, _floats(frames, "packet_phase_ns")[rows], chain, applied)
    advised = np.full(len(frames), np.nan)
    current_mean, current_var = _stats(error)
    what_if = [WhatIf(AS_RECORDED, current_mean, current_var, 0)]

    def advice(
        action: Action,
        shift_ns: float | None,
        expected: tuple[float, float],
        why: str,
        feedforward: FeedForwardReplay | None,
    ) -> Advice:
        """The recommendation: what every branch below shares, its own parts given."""
        return Advice(
            action=action,
            shift_ns=shift_ns,
            expected_mean_ns=expected[0],
            expected_var_ns2=expected[1],
            current_mean_ns=current_mean,
            floor=floor,
            why=why,
            what_if=what_if,
            advised_delay_ns=advised,
            feedforward=feedforward,
        )

    if not error.size:
        return advice(
            "none", None, (current_mean, current_var), "no paired frames: nothing to replay", None
        )
    shift = -float(np.median(error))
    shift_mean, shift_var = _stats(error + shift)
    what_if.append(WhatIf(CONSTANT_SHIFT, shift_mean, shift_var, 1))
    if seed is not None:
        what_if.append(
            WhatIf(SEED_CONTROLLER, seed.error_mean_ns, seed.error_var_ns2, seed.adjustments)
        )
    # Without recorded delays ours is replayed on relative ones (only differences count).
    known = np.isfinite(applied)
    ours = best_feedforward(error, np.where(known, applied, 0.0), exposure)
    what_if.append(WhatIf(FEEDFORWARD, ours.error_mean_ns, ours.error_var_ns2, ours.adjustments))
    margin = _margin_ns(current_mean)
    # At the floor (within the margin) nothing is left that a correction reliably removes:
    # a replay that dips below it follows the slowly wandering packet phase in-sample.
    at_floor = current_mean - floor.error_mean_ns < margin
    if at_floor or current_mean - min(shift_mean, ours.error_mean_ns) < margin:
        advised[rows] = applied
        why = _at_floor_why(current_mean, floor, min(shift_mean, ours.error_mean_ns))
        return advice("none", None, (current_mean, current_var), why, ours)
    # A shift that reaches the floor is the advice: it is one number, the same every frame.
    reaches_floor = shift_mean - floor.error_mean_ns < margin
    if reaches_floor or shift_mean - ours.error_mean_ns < margin:
        advised[rows] = np.where(known, applied + shift, np.nan)
        tail = (
            f"the floor of this trigger design ({floor.error_mean_ns / 1e3:.1f} us)"
            if reaches_floor
            else f"as low as our per-frame controller ({ours.error_mean_ns / 1e3:.1f} us)"
        )
        why = (
            f"a constant shift of the trigger by {shift / 1e3:+.1f} us lowers Eq. 5 from "
            f"{current_mean / 1e3:.1f} to {shift_mean / 1e3:.1f} us, {tail}"
        )
        return advice("shift_trigger", shift, (shift_mean, shift_var), why, ours)
    advised[rows] = np.where(known, applied + (ours.errors_ns - error), np.nan)
    why = (
        f"the error follows {_follows(error, exposure)}, which no constant removes: "
        f"feed-forward of the exposure lowers Eq. 5 from {current_mean / 1e3:.1f} to "
        f"{ours.error_mean_ns / 1e3:.1f} us (floor {floor.error_mean_ns / 1e3:.1f} us), "
        f"a constant shift of {shift / 1e3:+.1f} us only to {shift_mean / 1e3:.1f} us"
    )
    expected = (ours.error_mean_ns, ours.error_var_ns2)
    return advice("per_frame_compensation", None, expected, why, ours)


def _follows(error_ns: NDArray[np.float64], exposure_ns: NDArray[np.float64]) -> str:
    """What the error follows, for the sentence: the exposure (with its range) or a
    per-frame term."""
    lo, hi = float(exposure_ns.min()), float(exposure_ns.max())
    if hi - lo > 0 and error_ns.size > 2:
        r = float(np.corrcoef(error_ns, exposure_ns)[0, 1])
        if math.isfinite(r) and abs(r) >= 0.5:
            return f"the exposure ({lo / 1e6:.1f} to {hi / 1e6:.1f} ms, correlation {r:+.2f})"
    return "a per-frame term"


def _at_floor_why(current_ns: float, floor: ErrorFloor, best_ns: float) -> str:
    parts = []
    if math.isfinite(floor.quantisation_ns) and floor.trigger == "packet":
        parts.append(f"trigger quantised to packets, {floor.quantisation_ns / 1e3:.0f} us std")
    if math.isfinite(floor.jitter_ns):
        parts.append(f"chain jitter {floor.jitter_ns / 1e3:.0f} us std")
    source = f" ({', '.join(parts)})" if parts else ""
    return (
        f"at its floor: Eq. 5 {current_ns / 1e3:.1f} us against {floor.error_mean_ns / 1e3:.1f} "
        f"us this trigger design can reach{source}; the best replayed change reaches "
        f"{best_ns / 1e3:.1f} us"
    )
