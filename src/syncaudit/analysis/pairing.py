"""Which trigger and which LiDAR revolution each camera frame belongs to.

Frames pair with triggers by sequence number when the numbers can be trusted (both count
the same messages, see `camera.sequences`, and agree in time), else by time. Frames pair with revolutions through the packet their trigger names: that packet
lies a few packets before or after the zero crossing that started the revolution
(drivers differ in which packet they trigger from), so it pairs with the nearest zero
*crossing* time; frames whose trigger names no packet pair with the nearest crossing of
the camera centre instead.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from syncaudit.analysis.stamps import MISSING_NS, delta_ns, present, stamps_ns
from syncaudit.columns.distinct import distinct
from syncaudit.columns.lidar import RevolutionColumns
from syncaudit.columns.sequence_counter import SequenceCounter
from syncaudit.columns.table import Table

PAIR_TOLERANCE_NS = 50_000_000
"""A trigger belongs to a frame when it precedes the exposure by less than this."""
PAIR_LEAD_NS = 1_000_000
"""...or follows it by at most this: a frame's exposure start derived from its header stamp
and a rounded exposure (ImageMetaData holds whole microseconds: `exposure_end` stamps give a
start up to 0.5 us early) may fall just before the trigger's own record of it (248)."""
SEQUENCE_AGREEMENT = 0.9
"""Sequence pairing is trusted when this share of its pairs also agree in time."""
BY_SEQUENCE = "sequence number"
BY_TIME = "time"
NO_TRIGGERS = "none"
"""How frames were paired with their triggers (`TriggerPairing.method`)."""
PHASE_FROM_TRIGGER = "trigger packet"
PHASE_FROM_TRACKER = "tracker zero packet"


def nearest_index(sorted_values: NDArray[np.int64], query: NDArray[np.int64]) -> NDArray[np.int64]:
    """Index of the nearest element of a sorted int64 array for each query (exact)."""
    idx = np.searchsorted(sorted_values, query)
    idx = np.clip(idx, 1, max(sorted_values.size - 1, 1))
    left = sorted_values[idx - 1]
    right = sorted_values[np.minimum(idx, sorted_values.size - 1)]
    choose_left = np.abs(query - left) <= np.abs(right - query)
    return np.where(choose_left, idx - 1, idx).astype(np.int64)


def _frame_time_ns(frames: Table) -> NDArray[np.int64]:
    """When a frame was exposed: its exposure start, else its header stamp."""
    start = stamps_ns(frames, "exposure_start_ns")
    header = stamps_ns(frames, "header_stamp_ns")
    return np.where(present(start), start, header)


def _trigger_time_ns(triggers: Table, *, at_trigger: bool = False) -> NDArray[np.int64]:
    """When a trigger started its exposure: checkpoint 248, else 246.

    `at_trigger`: checkpoint 246 wherever recorded, to pair with frames whose time is the
    trigger itself (header stamps marking the trigger, before t4 is known).
    """
    start = stamps_ns(triggers, "exposure_start_ns")
    sensor = stamps_ns(triggers, "camera_sensor_ns")
    if at_trigger and present(sensor).any():
        return sensor
    return start if present(start).any() else sensor


def incomparable(frames: SequenceCounter, triggers: SequenceCounter) -> str | None:
    """Why the two counters cannot pair frames with triggers (None: they count alike).

    Alike: both count one and the same camera's frames, or both are the header.seq of
    topics the same cameras share (one publisher per topic, publishing every camera's
    frames in the same order on each).
    """
    if frames.cameras == triggers.cameras:  # a field counter counts one camera only
        return None
    return (
        f"the frames' numbers are {frames.describe()}, the triggers' are "
        f"{triggers.describe()}: they do not count the same messages"
    )


def sequence_problem(
    frames: Table,
    triggers: Table,
    counters: tuple[SequenceCounter, SequenceCounter] | None = None,
) -> str | None:
    """Why sequence numbers cannot pair these frames and triggers (None: they can).

    Usable numbers are present everywhere, count the same messages on both sides
    (`counters`: what the frames' and the triggers' numbers count; a ROS 1 header.seq of a
    topic several cameras share counts all their messages), are unique, increase with log
    time on both sides, and the frames they pair agree in time with their triggers (ROS 1
    bags converted from ROS 2, or drivers that leave `seq` alone, have 0 everywhere).
    """
    for what, table in (("frame", frames), ("trigger", triggers)):
        seq = table["frame_sequence"]
        missing = int(np.sum(~present(seq)))
        if missing:
            return f"{missing} of {len(seq)} {what}s have no sequence number"
        n_distinct = distinct(seq).size
        if n_distinct != len(seq):
            return f"{what} sequence numbers repeat ({n_distinct} distinct in {len(seq)})"
    if counters is not None and (mismatch := incomparable(*counters)) is not None:
        return mismatch
    for what, table in (("frame", frames), ("trigger", triggers)):
        seq = table["frame_sequence"]
        ordered = seq[np.argsort(table["log_time_ns"], kind="stable")]
        if len(ordered) > 1 and not bool((np.diff(ordered) > 0).all()):
            return f"{what} sequence numbers do not increase with log time"
    frame_rows, trigger_rows = _same_sequence(frames["frame_sequence"], triggers["frame_sequence"])
    if not frame_rows.size:
        return "no frame sequence number matches a trigger's"
    gap = delta_ns(_frame_time_ns(frames)[frame_rows], _trigger_time_ns(triggers)[trigger_rows])
    timed = np.isfinite(gap)
    if timed.any():
        agree = float(np.mean(np.abs(gap[timed]) < PAIR_TOLERANCE_NS))
        if agree < SEQUENCE_AGREEMENT:
            return (
                f"only {agree:.0%} of the frames paired by sequence number are within "
                f"{PAIR_TOLERANCE_NS / 1e6:g} ms of their trigger"
            )
    return None


def _same_sequence(
    frame_seq: NDArray[np.int64], trigger_seq: NDArray[np.int64]
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """(frame rows, trigger rows) with equal sequence numbers, in frame order; each side's
    numbers are unique (`sequence_problem` checked)."""
    order = np.argsort(trigger_seq, kind="stable")
    ranked = trigger_seq[order]
    at = np.minimum(np.searchsorted(ranked, frame_seq), max(ranked.size - 1, 0))
    hit = ranked[at] == frame_seq if ranked.size else np.zeros(frame_seq.size, dtype=bool)
    return np.flatnonzero(hit).astype(np.int64), order[at[hit]].astype(np.int64)


def _unset_as_missing(triggers: Table) -> Table:
    """Checkpoint stamps of 0 (a `builtin_interfaces/Time` the driver never set) as missing."""
    stamps = [
        c
        for c in triggers.columns
        if c.endswith("_ns") and c not in ("log_time_ns", "applied_delay_ns")
    ]
    unset = {c: triggers[c] == 0 for c in stamps}
    if not any(bool(m.any()) for m in unset.values()):
        return triggers
    return triggers.with_columns(
        {c: np.where(mask, MISSING_NS, triggers[c]) for c, mask in unset.items()}
    )


@dataclass(frozen=True, slots=True)
class TriggerPairing:
    """Frames with their trigger's checkpoints (`trig_*`), and how they were paired."""

    frames: Table
    method: str
    """`BY_SEQUENCE`, `BY_TIME` or `NO_TRIGGERS`."""
    reason: str | None
    """Why not by sequence number, where by time (None otherwise)."""
    warning: str | None
    """The reason as a warning, where both sides had numbers that could not be used."""


def pair_triggers(
    frames: Table, triggers: Table, *, trigger_stamped: bool = False
) -> tuple[Table, str | None]:
    """Frames with their trigger's checkpoints, and a warning if any (see `pair_frames`)."""
    pairing = pair_frames(frames, triggers, trigger_stamped=trigger_stamped)
    return pairing.frames, pairing.warning


def pair_frames(
    frames: Table,
    triggers: Table,
    *,
    trigger_stamped: bool = False,
    counters: tuple[SequenceCounter, SequenceCounter] | None = None,
) -> TriggerPairing:
    """Frames with their trigger's checkpoints (`trig_*`), and the method used.

    By sequence number where `sequence_problem` finds none (`counters`: what each side's
    numbers count), else by time: the latest trigger at most `PAIR_TOLERANCE_NS` before
    the frame's exposure (its header stamp where it has no exposure metadata), or at most
    `PAIR_LEAD_NS` after it. `trigger_stamped`: the frames' times are their triggers
    (checkpoint 246, the rig's `stamp: trigger`), so they pair with the triggers' 246
    rather than their 248, which lies t4 after.
    """
    checkpoint_cols = [c for c in triggers.columns if c.endswith("_ns") and c != "log_time_ns"]
    triggers = _unset_as_missing(triggers)
    # Per frame, the row of its trigger (-1: none).
    match = np.full(len(frames), -1, dtype=np.int64)
    method, problem, warning = NO_TRIGGERS, None, None
    if triggers.empty:
        pass
    elif (problem := sequence_problem(frames, triggers, counters)) is None:
        method = BY_SEQUENCE
        rows, trig_rows = _same_sequence(frames["frame_sequence"], triggers["frame_sequence"])
        match[rows] = trig_rows
    else:
        method = BY_TIME
        if present(frames["frame_sequence"]).any() and present(triggers["frame_sequence"]).any():
            warning = f"frames paired with triggers by time, not sequence number: {problem}"
        match = _match_by_time(frames, triggers, trigger_stamped=trigger_stamped)
    has = match >= 0
    safe = np.maximum(match, 0)
    trig = {
        f"trig_{c}": np.where(has, triggers[c][safe], MISSING_NS)
        if len(triggers)
        else np.full(len(frames), MISSING_NS, dtype=np.int64)
        for c in checkpoint_cols
    }
    return TriggerPairing(frames.with_columns(trig), method, problem, warning)


def _match_by_time(frames: Table, triggers: Table, *, trigger_stamped: bool) -> NDArray[np.int64]:
    """Per frame, the latest trigger (row) at most the pairing window before its exposure
    shifted by `PAIR_LEAD_NS`; -1 where none (or the frame has no time). Among triggers of
    equal time, the last in the log's order."""
    when = _frame_time_ns(frames)
    timed = present(when)
    lead = when + PAIR_LEAD_NS
    trig_when = _trigger_time_ns(triggers, at_trigger=trigger_stamped)
    usable = np.flatnonzero(present(trig_when))
    usable = usable[np.argsort(trig_when[usable], kind="stable")]
    ranked = trig_when[usable]
    match = np.full(len(frames), -1, dtype=np.int64)
    if not ranked.size:
        return match
    at = np.searchsorted(ranked, lead, side="right") - 1
    window = PAIR_TOLERANCE_NS + PAIR_LEAD_NS
    ok = timed & (at >= 0)
    ok[ok] &= lead[ok] - ranked[at[ok]] <= window
    match[ok] = usable[at[ok]]
    return match


@dataclass(frozen=True, slots=True)
class RevolutionPairing:
    """Per frame: its revolution and the times the method measures from it."""

    revolution: NDArray[np.int64]
    """Row in the revolution columns, -1 where the frame has none."""
    revolution_start_ns: NDArray[np.int64]
    """Zero crossing of that revolution, host clock (`MISSING_NS` where none)."""
    t_estimated_ns: NDArray[np.int64]
    """Beam at the camera centre in that revolution, host clock (`MISSING_NS` where none)."""
    packet_phase_ns: NDArray[np.float64]
    """Zero crossing minus the stamp of the packet the trigger fired from."""
    phase_from_trigger: NDArray[np.bool_]
    """True where the phase is from the trigger's own packet, False from the tracker's."""
    trigger_turn_fraction: float | None = None
    """Where in the revolution the trigger packets lie (0..1 of a turn after the rig's zero
    crossing; near 0 or 1 when the rig's zero azimuth is where the triggers fire)."""
    zero_from_triggers: bool = False
    """Revolutions started at the triggers' azimuth (the rig states no zero azimuth)."""

    @property
    def t_rotate_ns(self) -> NDArray[np.float64]:
        """Per frame, zero crossing to the beam at the camera centre (Eq. 1 measured)."""
        return delta_ns(self.t_estimated_ns, self.revolution_start_ns)

    def phase_source(self) -> str:
        """Which packet the phases were measured from, for the report."""
        has = self.revolution >= 0
        trig = int(np.sum(has & self.phase_from_trigger))
        tracker = int(np.sum(has & ~self.phase_from_trigger))
        if not trig and not tracker:
            return "none"
        if not tracker:
            return PHASE_FROM_TRIGGER
        if not trig:
            return PHASE_FROM_TRACKER
        return f"mixed: {trig} {PHASE_FROM_TRIGGER}, {tracker} {PHASE_FROM_TRACKER}"


def pair_revolutions(
    frames: Table,
    revs: RevolutionColumns,
    t_l_ns: NDArray[np.int64],
    *,
    target_index: int,
    offset_ns: int,
    max_gap_ns: float,
    zero_from_triggers: bool = False,
) -> RevolutionPairing:
    """The revolution of each frame (see the module docstring); `offset_ns` is host - sensor.

    A trigger packet pairs with the nearest zero crossing no more than `max_gap_ns` (half a
    revolution) away; its packet phase is measured from that packet's recorded stamp. A
    frame without one (or whose packet time is near no crossing) pairs with the nearest
    crossing of the camera centre to its mid-exposure `t_l_ns`, and takes the phase of the
    tracker's zero packet.

    `zero_from_triggers` (the rig does not state the zero azimuth): revolutions start
    where the triggers fire instead, `trigger_turn_fraction` of a turn after the tracker's
    crossings; each frame's camera crossing is the first one after that virtual start.
    """
    n = len(frames)
    rev = np.full(n, -1, dtype=np.int64)
    from_trigger = np.zeros(n, dtype=np.bool_)
    phase = np.full(n, np.nan)
    if not revs.count:
        missing = np.full(n, MISSING_NS, dtype=np.int64)
        return RevolutionPairing(rev, missing, missing.copy(), phase, from_trigger)
    zero_host = revs.zero_crossing_sensor_ns + offset_ns
    cross = revs.crossing_sensor_ns[:, target_index]
    cross_host = np.where(cross >= 0, cross + offset_ns, MISSING_NS)
    pkt = stamps_ns(frames, "trig_lidar_packet_ns")
    has_pkt = present(pkt)
    fraction = None
    if has_pkt.any():
        query = pkt[has_pkt]
        idx = nearest_index(zero_host, query)
        close = np.abs(zero_host[idx] - query) <= max_gap_ns
        fraction = trigger_turn_fraction(zero_host, query)
        if zero_from_triggers and fraction is not None:
            idx, close = _after_virtual_zero(zero_host, cross_host, query, fraction)
        rows = np.flatnonzero(has_pkt)[close]
        rev[rows] = idx[close]
        from_trigger[rows] = True
        phase[rows] = (zero_host[idx[close]] - query[close]).astype(np.float64)
    # A packet time far from every crossing (0 from a driver that leaves it unset, or
    # outside the LiDAR's span) says nothing: such frames pair like those without one.
    no_pkt = ~from_trigger & present(t_l_ns)
    valid = np.flatnonzero(present(cross_host))
    if no_pkt.any() and valid.size:
        query = t_l_ns[no_pkt]
        idx = valid[nearest_index(cross_host[valid], query)]
        close = np.abs(cross_host[idx] - query) <= max_gap_ns
        rows = np.flatnonzero(no_pkt)[close]
        rev[rows] = idx[close]
        tracker = (revs.zero_crossing_sensor_ns - revs.zero_packet_sensor_ns).astype(np.float64)
        phase[rows] = tracker[idx[close]]
    has = rev >= 0
    start = np.where(has, zero_host[np.maximum(rev, 0)], MISSING_NS)
    t_est = np.where(has, cross_host[np.maximum(rev, 0)], MISSING_NS)
    virtual = zero_from_triggers and fraction is not None
    return RevolutionPairing(rev, start, t_est, phase, from_trigger, fraction, virtual)


def trigger_turn_fraction(zero_ns: NDArray[np.int64], packet_ns: NDArray[np.int64]) -> float | None:
    """Circular mean of where trigger packets fall in their revolution (0..1 of a turn).

    None when no packet lies inside a whole revolution.
    """
    if zero_ns.size < 2:
        return None
    r = np.searchsorted(zero_ns, packet_ns, side="right") - 1
    inside = (r >= 0) & (r < zero_ns.size - 1)
    if not inside.any():
        return None
    r = r[inside]
    period = (zero_ns[r + 1] - zero_ns[r]).astype(np.float64)
    angle = 2.0 * np.pi * (packet_ns[inside] - zero_ns[r]).astype(np.float64) / period
    mean = float(np.arctan2(np.sin(angle).mean(), np.cos(angle).mean()))
    return (mean / (2.0 * np.pi)) % 1.0


def _after_virtual_zero(
    zero_ns: NDArray[np.int64],
    cross_ns: NDArray[np.int64],
    packet_ns: NDArray[np.int64],
    fraction: float,
) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """Per packet, the revolution whose camera crossing first follows the virtual zero.

    The virtual zero of revolution r is `fraction` of its turn after its zero crossing
    (interpolated: the rate changes little within a turn; the turns before the first and
    after the last crossing take their neighbour's period). The packet pairs with the
    nearest virtual zero, and the camera crossing is the first at or after it.
    """
    count = zero_ns.size
    period = np.diff(zero_ns).astype(np.float64)
    turn = np.concatenate(([period[0]], period, [period[-1]]))  # revolutions -1 .. count-1
    start = np.concatenate(([zero_ns[0] - round(period[0])], zero_ns))
    virtual = start + np.rint(fraction * turn).astype(np.int64)
    near = nearest_index(virtual, packet_ns)
    r = near - 1
    close = np.abs(virtual[near] - packet_ns) <= 0.5 * turn[near]
    cross_r = np.where(r >= 0, cross_ns[np.maximum(r, 0)], MISSING_NS)
    after = present(cross_r) & (cross_r >= virtual[near])
    idx = np.where(after, r, r + 1)
    # Before the first crossing, revolution 0's camera crossing must be within one turn.
    first = (r < 0) & ~(present(cross_ns[0:1]) & (cross_ns[0] - virtual[near] < turn[near]))
    close &= (idx >= 0) & (idx < count) & ~first
    return np.clip(idx, 0, count - 1), close
