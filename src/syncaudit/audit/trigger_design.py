"""The audit's trigger-design step: per camera the design, its correction, rolling-shutter rows;
per rig the LiDAR's phase-lock health and, where the cameras are off together, its lock angle.

Everything here reads what `analysis.sync` already measured (each frame's signed error) and
the camera's trigger records; the analysis is in `analysis.designs`, `analysis.rolling_shutter`
and `analysis.phase_lock`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from syncaudit.analysis.designs import (
    design_setting,
    guess_design,
    lock_setting,
    recommendation,
    replay_shift,
)
from syncaudit.analysis.phase_lock import phase_lock_health
from syncaudit.analysis.rolling_shutter import per_row, row_offset_ns, row_timing
from syncaudit.analysis.stamps import present, stamps_ns
from syncaudit.audit.design_info import image_rows

if TYPE_CHECKING:
    from syncaudit.analysis.sync import CameraSync
    from syncaudit.columns.camera import CameraTables
    from syncaudit.columns.lidar import LidarScan
    from syncaudit.logs import LogReader
    from syncaudit.rig import CameraConfig, Rig

TOGETHER_SPREAD_NS = 50_000.0
"""Cameras whose shifts agree this closely (and exceed their scatter) are off together."""


def camera_design(
    rig: Rig,
    camera: CameraConfig,
    tables: CameraTables,
    sync: CameraSync,
    scan: LidarScan,
    offset_ns: int,
    rows_from_log: int | None = None,
) -> dict[str, Any]:
    """The camera's design (recognised or stated), its replayed correction and its rows
    (`rows_from_log`: the image height, where the rig gives a readout but no rows)."""
    triggers = tables.triggers
    trigger_ns = stamps_ns(triggers, "camera_sensor_ns") if not triggers.empty else None
    trigger_ns = trigger_ns[present(trigger_ns)] if trigger_ns is not None else np.empty(0, "i8")
    checkpoints = (
        bool(present(stamps_ns(triggers, "lidar_packet_ns")).any()) if not triggers.empty else False
    )
    frames = sync.table
    start = stamps_ns(frames, "exposure_start_ns")
    zero_host = scan.revolutions.zero_crossing_sensor_ns + offset_ns
    guess = guess_design(
        trigger_ns=trigger_ns,
        has_checkpoints=checkpoints,
        frame_ns=start[present(start)],
        zero_host_ns=zero_host,
        stated=rig.trigger.design,
    )
    paired = np.asarray(frames["paired"], dtype=bool)
    errors = np.where(paired, np.asarray(frames["error_signed_ns"], np.float64), np.nan)
    timing = row_timing(camera, rows_from_log)
    rows = None
    if timing is not None:
        rows = per_row(errors, timing)
        errors = errors + row_offset_ns(timing, timing.target_row)
    replay = replay_shift(errors)
    setting = design_setting(
        guess,
        replay.shift_ns,
        omega_deg_s=sync.omega_deg_s,
        sync_output_angle_deg=rig.trigger.sync_output_angle_deg,
        applied_delay_ns=sync.delay_applied_ns,
    )
    extra = (
        f"at row {timing.target_row} of {timing.rows} (rolling shutter, "
        f"{timing.readout_ns / 1e3:.0f} us readout)"
        if timing is not None
        else ""
    )
    advice = recommendation(
        guess, replay, setting, threshold_ns=rig.thresholds.error_mean_us * 1e3, why_extra=extra
    )
    return {**guess.to_dict(), "recommendation": advice, "rolling_shutter": rows}


def lidar_phase_lock(rig: Rig, scan: LidarScan, start_sensor_ns: int) -> dict[str, Any]:
    """The LiDAR's phase-lock health (sensor clock)."""
    revs = scan.revolutions
    return phase_lock_health(
        revs.zero_crossing_sensor_ns,
        revs.omega_deg_s,
        zero_azimuth_deg=rig.lidar.zero_azimuth_deg,
        lock_azimuth_deg=rig.trigger.lidar_phase_lock_deg,
        start_ns=start_sensor_ns,
    )


def off_together(
    designs: list[dict[str, Any]],
    lock: dict[str, Any],
    *,
    vendor: str | None,
    omega_deg_s: float,
) -> dict[str, Any] | None:
    """Where every PTP-phase camera is off by the same time on a locked LiDAR, the LiDAR's
    lock angle is the one setting to change: put it in every camera's recommendation."""
    phase = [d for d in designs if d["design"] == "ptp_phase"]
    recs = [d["recommendation"] for d in phase]
    if len(phase) < 2 or not lock.get("locked") or len(phase) != len(designs):
        return None
    if any(r["action"] != "shift_trigger" for r in recs):
        return None
    shifts = [r["shift_us"] * 1e3 for r in recs]
    floors = [r["floor_us"] * 1e3 for r in recs]
    if max(shifts) - min(shifts) > max(TOGETHER_SPREAD_NS, 2.0 * max(floors)):
        return None
    common_error = -float(np.median(shifts))
    setting = lock_setting(vendor, lock["lock_azimuth_deg"], common_error, omega_deg_s)
    for design in phase:
        rec = design["recommendation"]
        rec["camera_set"] = rec["set"]
        rec["set"] = setting
        rec["why"] += (
            f"; all {len(phase)} cameras are off by {common_error / 1e3:+.1f} us together: "
            "move the LiDAR's lock angle instead of every camera's phase"
        )
    return {
        "cameras": len(phase),
        "common_error_us": round(common_error / 1e3, 3),
        "set": setting,
    }


class _Audited(Protocol):
    """A camera's audit as run.py holds it: its sync, and room for its design."""

    sync: CameraSync
    design: dict[str, Any] | None


CHAIN_WARNING = " not observed in the log (set analysis.assumed_"


def _drop_chain_warnings(sync: CameraSync, design: str) -> None:
    """t2..t4 are latencies of the method's chain: another design has none to observe."""
    kept = [w for w in sync.warnings if not (w[:2] in {"t2", "t3", "t4"} and CHAIN_WARNING in w)]
    if len(kept) != len(sync.warnings):
        kept.append(f"trigger design {design}: the chain's t2..t4 and t_sleep do not apply")
    sync.warnings[:] = kept


def add_designs(
    rig: Rig,
    scan: LidarScan,
    cameras: list[CameraConfig],
    tables: list[CameraTables],
    audits: Sequence[_Audited],
    *,
    offset_ns: int,
    start_ns: int | None,
    log: LogReader | None = None,
) -> dict[str, Any]:
    """Give every audited camera its design; return the rig's phase lock (and lock advice).

    `log` gives the image rows of rolling-shutter cameras whose rig states none.
    """
    for camera, camera_tables, audit in zip(cameras, tables, audits, strict=True):
        rows = None
        if log is not None and camera.readout_us is not None and camera.rows is None:
            rows = image_rows(log, camera)
        audit.design = camera_design(
            rig, camera, camera_tables, audit.sync, scan, offset_ns, rows_from_log=rows
        )
        if camera.readout_us is not None and audit.design["rolling_shutter"] is None:
            audit.sync.warnings.append(
                "readout_us given but no rows (rig rows, CameraInfo or Image height): "
                "the rolling-shutter rows are not computed"
            )
        if audit.design["design"] != "lidar_packet":
            _drop_chain_warnings(audit.sync, audit.design["design"])
    zero = scan.revolutions.zero_crossing_sensor_ns
    start = (start_ns - offset_ns) if start_ns is not None else (int(zero[0]) if zero.size else 0)
    lock = lidar_phase_lock(rig, scan, start)
    omega = [a.sync.omega_deg_s for a in audits if math.isfinite(a.sync.omega_deg_s)]
    designs = [a.design for a in audits if a.design is not None]
    if omega and lock.get("judged"):
        lock["move_lock"] = off_together(
            designs, lock, vendor=scan.vendor, omega_deg_s=float(np.median(omega))
        )
    return lock
