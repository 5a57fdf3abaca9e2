"""The zero-crossing azimuth of a rig that does not state it, from where the triggers fire.

A packet-triggered camera fires from the packet in which the beam crosses the rig's zero
azimuth, so that azimuth lies inside every trigger packet: at or after the azimuth at the
packet's stamp, less than one packet's span later. Packets drift over the azimuth from
turn to turn (a rate is never a whole number of packets per turn), so the trigger packets'
azimuths spread over up to one span and the zero lies in [latest, earliest + span]: the
guess is the middle of that interval. The audit then tracks revolutions from the guess, as
if the rig had said it, so theta, t_rotate and the packet phase (within one packet period)
are those a rig with that zero azimuth gives.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FULL_TURN_DEG = 360.0

__all__ = ["ZERO_MISMATCH_TURNS", "ZeroGuess", "guess_zero_azimuth", "zero_mismatch_warning"]

ZERO_MISMATCH_TURNS = 0.125
"""Trigger packets this far (in turns) from the rig's zero crossing: the rig is suspect."""


@dataclass(frozen=True, slots=True)
class ZeroGuess:
    """The guessed zero azimuth and what it rests on."""

    zero_azimuth_deg: float
    triggers: int
    """Trigger packets whose azimuth was found."""
    earliest_deg: float
    latest_deg: float
    """The trigger packets' azimuths at their stamps (vendor azimuth, degrees)."""
    packet_span_deg: float

    @property
    def note(self) -> str:
        """One line for the audit's `guessed` list and its warning."""
        return (
            f"lidar.zero_azimuth_deg {self.zero_azimuth_deg:.2f} from where the triggers "
            f"fire ({self.triggers} trigger packets stamped at azimuth "
            f"{self.earliest_deg:.1f}-{self.latest_deg:.1f} deg, a packet spans "
            f"{self.packet_span_deg:.2f} deg)"
        )


def guess_zero_azimuth(
    packet_azimuth_deg: NDArray[np.float64],
    *,
    packets_per_revolution: float,
    azimuth_increases: bool = True,
) -> ZeroGuess | None:
    """The zero azimuth inside every trigger packet, from their azimuths at their stamps.

    `packet_azimuth_deg` is each trigger packet's azimuth at its stamp (NaN: not found).
    The packet span holding the most of them decides; the others (a lost trigger packet,
    interpolation at the crossing) are left out. None without a trigger packet or a rate.
    """
    found = packet_azimuth_deg[np.isfinite(packet_azimuth_deg)]
    if not found.size or not (math.isfinite(packets_per_revolution) and packets_per_revolution):
        return None
    sign = 1.0 if azimuth_increases else -1.0
    oriented = (sign * found) % FULL_TURN_DEG
    angle = np.radians(oriented)
    mean = math.degrees(math.atan2(float(np.sin(angle).mean()), float(np.cos(angle).mean())))
    spread = np.sort((oriented - mean + 180.0) % FULL_TURN_DEG - 180.0)
    span = FULL_TURN_DEG / packets_per_revolution
    ends = np.searchsorted(spread, spread + span, side="left")  # window [d_i, d_i + span)
    first = int(np.argmax(ends - np.arange(spread.size)))
    lo, hi = float(spread[first]), float(spread[ends[first] - 1])
    zero = mean + (hi + lo + span) / 2.0
    return ZeroGuess(
        zero_azimuth_deg=(sign * zero) % FULL_TURN_DEG,
        triggers=int(found.size),
        earliest_deg=(sign * (mean + (lo if sign > 0 else hi))) % FULL_TURN_DEG,
        latest_deg=(sign * (mean + (hi if sign > 0 else lo))) % FULL_TURN_DEG,
        packet_span_deg=span,
    )


def zero_mismatch_warning(
    trigger_turn_fraction: float | None, zero_azimuth_deg: float, *, azimuth_increases: bool
) -> str | None:
    """The one warning, for the LiDAR, where its triggers fire far from the rig's zero.

    `trigger_turn_fraction` is where every camera's trigger packets fall in their
    revolution (0..1 of a turn past the zero crossing; None: no trigger packet).
    """
    if trigger_turn_fraction is None:
        return None
    off = min(trigger_turn_fraction, 1.0 - trigger_turn_fraction)
    if off <= ZERO_MISMATCH_TURNS:
        return None
    step = FULL_TURN_DEG * trigger_turn_fraction
    fired = (zero_azimuth_deg + (step if azimuth_increases else -step)) % FULL_TURN_DEG
    return (
        f"the triggers fire near packet azimuth {fired:.1f} deg, {off * FULL_TURN_DEG:.0f} deg "
        f"from the rig's zero_azimuth_deg {zero_azimuth_deg:g}: check the rig (frames "
        "may pair with the wrong revolution)"
    )
