"""Cross-LiDAR check: the vehicle's motion every LiDAR's pair alignments imply must agree."""

from __future__ import annotations

import dataclasses

from syncaudit.calib import extrinsics as extr
from syncaudit.calib import se3
from syncaudit.calib.alignment import consensus
from syncaudit.calib.alignment.pairs import align_pair
from syncaudit.calib.alignment.registration import Alignment
from syncaudit.calib.settings import CalibConfig
from syncaudit.calib.state import LidarState

_MAX_DISAGREEMENT_M = 0.3
_MAX_DISAGREEMENT_DEG = 3.0
_RESEED_M = 0.2
_RESEED_DEG = 2.0
"""A pair alignment whose vehicle motion (through the recorded extrinsic) is more than
`_MAX_DISAGREEMENT_M` / `_MAX_DISAGREEMENT_DEG` from what all LiDARs' other alignments
agree on is rejected; stops whose agreed pose is more than `_RESEED_M` / `_RESEED_DEG`
from the coarse motion get that pose as their seed and their pairs are aligned again."""


def _vehicle_motions(
    lidars: list[LidarState], recorded: extr.RecordedExtrinsics
) -> list[consensus.Motion]:
    """Every accepted pair alignment as the vehicle's motion in the base frame."""
    out = []
    for lidar in lidars:
        base = recorded.base_from_frame[lidar.frame_id]
        base_inv = se3.invert(base)
        for (a, b), res in sorted(lidar.results.items()):
            if res.accepted:
                motion = base @ res.target_from_source @ base_inv
                out.append(consensus.Motion(lidar.topic, a, b, motion))
    return out


def _reject_misfits(lidars: list[LidarState], agreed: consensus.Consensus) -> list[str]:
    """Mark the alignments the cross-LiDAR check removed as rejected; one line each."""
    by_topic = {lidar.topic: lidar for lidar in lidars}
    lines = []
    for misfit in agreed.removed:
        m = misfit.motion
        lidar = by_topic[m.source]
        why = (
            f"inconsistent: the vehicle's motion it implies is {misfit.translation_m * 100:.0f} "
            f"cm / {misfit.rotation_deg:.1f} deg from what the other alignments of all LiDARs "
            "agree on (through the recorded extrinsics)"
        )
        lidar.results[(m.first, m.second)] = dataclasses.replace(
            lidar.results[(m.first, m.second)], accepted=False, reason=why
        )
        lines.append(f"{m.source} {m.first}->{m.second} ({misfit.translation_m * 100:.0f} cm)")
    return lines


def _measures(result: Alignment) -> bool:
    """Whether an alignment converged onto the scene (accepted, or rejected only for a
    weak direction), so its motion can be compared with another LiDAR's."""
    return result.accepted or (result.reason or "").startswith(("degenerate", "slid"))


def _cross_seed(
    lidars: list[LidarState], recorded: extr.RecordedExtrinsics, config: CalibConfig
) -> list[str]:
    """Pairs of stops aligned by two LiDARs whose vehicle motions disagree: each is aligned
    again from the other LiDAR's motion, and the new result replaces the old one when it
    fits this LiDAR's own scans better (more overlap and a smaller error): the old one sat
    in a local minimum. One line per replacement."""
    motions = {
        (lidar.topic, key): recorded.base_from_frame[lidar.frame_id]
        @ res.target_from_source
        @ se3.invert(recorded.base_from_frame[lidar.frame_id])
        for lidar in lidars
        for key, res in lidar.results.items()
        if _measures(res)
    }
    lines = []
    for lidar in lidars:
        base = recorded.base_from_frame[lidar.frame_id]
        for (a, b), mine in sorted(lidar.results.items()):
            if not _measures(mine):
                continue
            for other in lidars:
                theirs = motions.get((other.topic, (a, b)))
                if other is lidar or theirs is None:
                    continue
                rot_deg, trans_m = se3.transform_difference(motions[(lidar.topic, (a, b))], theirs)
                if rot_deg <= _MAX_DISAGREEMENT_DEG and trans_m <= _MAX_DISAGREEMENT_M:
                    continue
                initial = se3.invert(base) @ theirs @ base
                again = align_pair(lidar, a, b, initial, config)
                if (
                    again.after.overlap > mine.after.overlap
                    and again.after.rmse_m < mine.after.rmse_m
                ):
                    lidar.results[(a, b)] = again
                    lines.append(
                        f"{lidar.topic} {a}->{b} ({trans_m * 100:.0f} cm from {other.topic}; "
                        f"overlap {mine.after.overlap:.0%} -> {again.after.overlap:.0%}, error "
                        f"{mine.after.rmse_m * 100:.1f} -> {again.after.rmse_m * 100:.1f} cm)"
                    )
                    break
    return lines


def cross_check(
    lidars: list[LidarState],
    recorded: extr.RecordedExtrinsics,
    reference: int,
    config: CalibConfig,
    notes: list[str],
) -> None:
    """The vehicle's motion seen by every LiDAR must agree (through the recorded extrinsics).

    First per pair of stops: an alignment that disagrees with another LiDAR's of the same
    pair is aligned again from it and replaced when that fits better (`_cross_seed`). Then
    over loops: reject pair alignments that contradict the vehicle motion all the others
    agree on, re-seed the stops the coarse motion misplaced from that agreement and align
    their pairs again, then check once more.

    Catches a wrong coarse link whose pair alignment converged next to it (seeded there):
    measured on a bumper 64-beam drive, the coarse motion 5->6 was 1.15 m off and the front
    LiDAR's 5-6 alignment, accepted, placed stops 6-10 of its map 1.38 m off, while the rear
    LiDAR's alignments across that link, seeded from the same wrong motion, moved to the
    right one. With 8 stops no loop closes over that link; there the rear LiDAR's own 5-6
    alignment (degenerate, rejected, but 0.5 cm right) seeds the front's again, which then
    fits better (overlap 30 -> 34 %, error 2.3 -> 1.8 cm) and lands 1 cm from the truth."""
    swapped = _cross_seed(lidars, recorded, config)
    if swapped:
        notes.append(
            "cross-LiDAR check: alignment(s) disagreeing with another LiDAR's view of the same "
            "motion were aligned again from it and fit their own scans better: "
            + "; ".join(swapped)
        )
    kwargs = {"max_translation_m": _MAX_DISAGREEMENT_M, "max_rotation_deg": _MAX_DISAGREEMENT_DEG}
    agreed = consensus.consensus(_vehicle_motions(lidars, recorded), reference, **kwargs)
    lines = _reject_misfits(lidars, agreed)
    if agreed.removed:
        for lidar in lidars:
            base = recorded.base_from_frame[lidar.frame_id]
            moved = set()
            for k, pose in agreed.poses.items():
                if k not in lidar.chain:
                    continue
                seed = se3.invert(base) @ pose @ base
                rot_deg, trans_m = se3.transform_difference(lidar.chain[k], seed)
                if rot_deg > _RESEED_DEG or trans_m > _RESEED_M:
                    lidar.chain[k] = seed
                    moved.add(k)
            for a, b, _sep, _pred in lidar.candidates:
                if a in moved or b in moved:
                    initial = se3.invert(lidar.chain[a]) @ lidar.chain[b]
                    lidar.results[(a, b)] = align_pair(lidar, a, b, initial, config)
        agreed = consensus.consensus(_vehicle_motions(lidars, recorded), reference, **kwargs)
        lines += _reject_misfits(lidars, agreed)
    if lines:
        notes.append(
            "cross-LiDAR check: pair alignment(s) contradicting the vehicle's motion that the "
            f"others agree on were rejected ({', '.join(lines)}); the stops the coarse motion "
            "had misplaced were re-seeded from that agreement and aligned again"
        )
    if agreed.unresolved is not None:
        m = agreed.unresolved
        notes.append(
            "cross-LiDAR check: the alignments disagree on the vehicle's motion by up to "
            f"{m.translation_m * 100:.0f} cm / {m.rotation_deg:.1f} deg (e.g. {m.motion.source} "
            f"{m.motion.first}->{m.motion.second}) and no single one is to blame"
        )
