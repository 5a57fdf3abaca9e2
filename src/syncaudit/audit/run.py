"""`audit_log`: the whole synchronisation audit of one log (part A of the method).

The steps, each its own function: probe the log (`audit.probe`: types, first messages,
`/tf_static`, Ouster metadata, each read once for every step), guess or check the rig,
place the cameras, read the log once (`audit.plan` through `logs.parallel`), find the
host-LiDAR clock offset, analyse each camera and replay its controller, assemble the result.
"""

from __future__ import annotations

import itertools
import multiprocessing
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from syncaudit.audit.health import LogHealth, log_health, no_packets_error
from syncaudit.audit.inspect import LidarRow, lidar_row, lidar_warnings
from syncaudit.audit.plan import read_plan
from syncaudit.audit.probe import LogProbe
from syncaudit.audit.rig_check import check_rig_against_log
from syncaudit.audit.rig_guess import guess_rig
from syncaudit.camera.azimuth import camera_azimuth, needs_tf_static
from syncaudit.columns.audit_result import SCHEMA_VERSION
from syncaudit.columns.camera import CameraTables
from syncaudit.columns.lidar import LidarScan, RevolutionColumns
from syncaudit.columns.table import MISSING
from syncaudit.errors import NoDataError
from syncaudit.lidar.cloud_scan import CloudFeeder
from syncaudit.lidar.scan import LidarScanner
from syncaudit.logs import LogReader, open_log
from syncaudit.logs.parallel import default_jobs, iter_items
from syncaudit.rig import CameraConfig, Rig
from syncaudit.units import finite_or_none, json_ready, ns_to_us
from syncaudit.workers import worker_pool

if TYPE_CHECKING:
    import pandas as pd

    from syncaudit.analysis.advice import Advice
    from syncaudit.analysis.controller import ControllerConfig
    from syncaudit.analysis.replay import ReplayResult
    from syncaudit.analysis.sync import CameraSync

__all__ = ["SCHEMA_VERSION", "AuditResult", "CameraAudit", "audit_log"]
MIN_ZERO_CROSSINGS = 2
"""A LiDAR is judged only with a whole revolution: two zero crossings."""


def _no_revolution(crossings: int, packets: int) -> str:
    return f"{crossings} zero crossing(s) in {packets} packets: no complete revolution to measure"


@dataclass(slots=True)
class CameraAudit:
    """One camera's audit plus what the replayed controller would have achieved."""

    sync: CameraSync
    azimuth_deg: float
    azimuth_source: str
    replay: ReplayResult | None
    advice: Advice
    design: dict[str, Any] | None = None
    """The trigger design, its correction and rolling-shutter rows (audit.trigger_design)."""

    def to_dict(self) -> dict[str, Any]:
        """JSON form."""
        out = self.sync.to_dict()
        out.update(self.advice.to_dict())
        out["azimuth_deg"] = self.azimuth_deg
        out["azimuth_source"] = self.azimuth_source
        out["corrected"] = (
            None
            if self.replay is None
            else {
                "adjustments": self.replay.adjustments,
                "final_delay_us": self.replay.final_delay_ns / 1e3,
                "error_mean_us": ns_to_us(self.replay.error_mean_ns),
                "error_var_us2": finite_or_none(self.replay.error_var_ns2 / 1e6),
                "error_signed_mean_us": ns_to_us(self.replay.error_signed_mean_ns),
                "settled_error_mean_us": ns_to_us(self.replay.settled_error_mean_ns),
                "settled_error_var_us2": finite_or_none(self.replay.settled_error_var_ns2 / 1e6),
            }
        )
        out["trigger_design"] = self.design
        design_advice = (self.design or {}).get("recommendation")
        setting = design_advice.get("set") if isinstance(design_advice, dict) else None
        if setting and out["recommendation"]["action"] == "shift_trigger":
            # The same shift (minus the median error), in the units the design is set in.
            out["recommendation"]["set"] = setting
        return out


@dataclass(slots=True)
class AuditResult:
    """The audit of one log."""

    path: str
    container: str
    duration_s: float | None
    rig: Rig
    lidar: LidarRow
    clock_offset_ns: int
    cameras: list[CameraAudit] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)
    guessed: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    start_ns: int | None = None
    """Log start (host clock), the origin of the report's time axes."""
    revolutions: RevolutionColumns | None = field(default=None, repr=False)
    """The LiDAR's per-revolution timing (RPM, drops, clock offset over time)."""
    health: LogHealth = field(default_factory=LogHealth)
    """The file's condition: cut off, damaged messages skipped, no index."""
    phase_lock: dict[str, Any] | None = None
    """The LiDAR's phase-lock health (audit.trigger_design)."""

    @property
    def not_judged(self) -> list[str]:
        """What the audit could not judge and must: required cameras and the LiDAR."""
        reasons = [
            f"camera {c.sync.camera}: {c.sync.not_judged_reason}"
            for c in self.cameras
            if not c.sync.judged and not c.sync.optional
        ]
        crossings = self.lidar.revolutions if self.revolutions is None else self.revolutions.count
        if crossings < MIN_ZERO_CROSSINGS:
            why = _no_revolution(crossings, self.lidar.packets)
            reasons.insert(0, f"LiDAR topic {self.lidar.topic}: {why}")
        return reasons

    @property
    def verdict(self) -> str:
        """'pass', 'fail' (a judged camera crossed a threshold), 'not judged' or 'no cameras'."""
        if not self.cameras:
            return "no cameras"
        if any(c.sync.judged and c.sync.needs_correction for c in self.cameras):
            return "fail"
        return "not judged" if self.not_judged else "pass"

    @property
    def passed(self) -> bool:
        """Every required camera was judged and none crossed a threshold."""
        return self.verdict == "pass"

    def frames(self) -> pd.DataFrame:
        """Per-frame table of every camera (what --csv writes); stamps are Int64 ns."""
        import pandas as pd

        tables = [c.sync.frames for c in self.cameras]
        return pd.concat(tables, ignore_index=True) if tables else pd.DataFrame()

    def to_dict(self) -> dict[str, Any]:
        """JSON form (schemas/audit.schema.json)."""
        cleaned: dict[str, Any] = json_ready(
            {
                "schema_version": SCHEMA_VERSION,
                "path": self.path,
                "container": self.container,
                "duration_s": self.duration_s,
                "verdict": self.verdict,
                "not_judged": self.not_judged,
                "lidar": _row(self.lidar),
                "clock_offset_s": self.clock_offset_ns / 1e9,
                "thresholds": self.rig.thresholds.model_dump(),
                "analysis": self.rig.analysis.model_dump(),
                "cameras": [c.to_dict() for c in self.cameras],
                "missing": self.missing,
                "guessed": self.guessed,
                "warnings": self.warnings,
                "health": self.health.to_dict(),
                "phase_lock": self.phase_lock,
            }
        )
        return cleaned


def _row(row: Any) -> dict[str, Any]:
    return {name: getattr(row, name) for name in row.__slots__}


def audit_log(
    path: str | Path,
    rig: Rig | None = None,
    *,
    jobs: int | None = None,
    check_crc: bool = False,
    meanwhile: Callable[[], object] | None = None,
    lidar_metadata: str | Path | None = None,
    lidar_capture: str | Path | None = None,
) -> AuditResult:
    """Audit the LiDAR-camera synchronisation of a log; `rig=None` guesses topics.
    `lidar_metadata` / `lidar_capture`: as `logs.open_log` (the LiDAR from a capture).

    `jobs` worker processes extract an indexed MCAP's chunks in parallel (default: one
    per core); other containers, and `jobs=1`, read serially. The result is the same.
    `check_crc` verifies every MCAP chunk's CRC (as the mcap reader, off by default: a
    damaged zstd/lz4 chunk fails to decompress anyway, and CRCs cost about as much CPU as
    the decompression). `meanwhile` is the caller's own work for later (e.g. importing
    what renders the result), run once while worker processes read, where it overlaps
    them, or before a serial read.

    Raises:
        LogOpenError, LogReadError, UnknownTypeError, DecodeError: the log cannot be read.
        NoDataError: the log holds nothing to audit (no messages, no LiDAR packets).
    """
    with open_log(path, lidar_metadata=lidar_metadata, lidar_capture=lidar_capture) as log:
        if log.summary.message_count == 0:
            raise NoDataError(f"{log.summary.path}: the log holds no messages")
        probe = LogProbe(log)
        rig, guessed = _rig_for(probe, rig)
        jobs = default_jobs() if jobs is None else max(1, jobs)
        return _audit(probe, rig, guessed, jobs, check_crc, meanwhile)


def _rig_for(probe: LogProbe, rig: Rig | None) -> tuple[Rig, list[str]]:
    """The rig to audit with (given, else guessed from the log) and what was guessed."""
    if rig is None:
        return guess_rig(probe)
    if rig.lidar.topic not in probe.topics:
        raise NoDataError(f"LiDAR topic {rig.lidar.topic} (from the rig) is not in the log")
    return rig, []


def _import_analysis() -> None:
    """Import the analysis while the extraction workers read their first tasks, rather
    than before they start or after the last item, when it would add to the wall time."""
    # Import statements, not importlib: `python -X importtime` names only those.
    import syncaudit.analysis.advice  # and analysis.feedforward, analysis.floor
    import syncaudit.analysis.replay  # and analysis.controller
    import syncaudit.analysis.sync  # noqa: F401


def _meanwhile(caller: Callable[[], object] | None) -> Callable[[], object]:
    """What `_read` runs while workers read: the analysis' imports, then the caller's work."""

    def both() -> None:
        _import_analysis()
        if caller is not None:
            caller()

    return both


Located = tuple[CameraConfig, float, str]
"""A camera the audit can place: its config, centre azimuth and where that came from."""


def _locate_cameras(probe: LogProbe, rig: Rig, warnings: list[str]) -> list[Located]:
    """Cameras with a known centre azimuth (rig, or /tf_static with the vendor's +X)."""
    # /tf_static is read (and its types built) only for cameras the rig gives no angle.
    tf_yaws = probe.tf_yaws() if any(needs_tf_static(c) for c in rig.cameras) else {}
    vendor = probe.family(rig.lidar.topic) or rig.lidar.vendor
    located: list[Located] = []
    for cam in rig.cameras:
        azimuth, source = camera_azimuth(cam, rig.lidar, tf_yaws, vendor)
        if azimuth is None:
            warnings.append(f"camera {cam.name} skipped: {source}")
            continue
        located.append((cam, azimuth, source))
    return located


def _read(
    probe: LogProbe,
    rig: Rig,
    located: list[Located],
    *,
    jobs: int,
    check_crc: bool,
    warnings: list[str],
    meanwhile: Callable[[], object] | None = None,
    cameras: bool = True,
) -> tuple[LidarScanner, LidarScan, list[CameraTables]]:
    """One pass over the log: the LiDAR's reduced timing and every camera's tables (none
    without `cameras`: the LiDAR's topics alone are read, its revolutions still timed at
    every camera's azimuth).

    What could not be given to a camera from a topic cameras share is added to `warnings`.
    Where the rig does not state the zero azimuth the scanner keeps its samples, to track
    the revolutions again from the guessed one (`_zero_from_triggers`).
    """
    lidar_cfg = rig.lidar
    scanner = LidarScanner.create(
        lidar_cfg.topic,
        zero_azimuth_deg=lidar_cfg.zero_azimuth_deg,
        azimuth_increases=lidar_cfg.azimuth_increases,
        target_azimuth_deg=tuple(a for _, a, _ in located),
        clock_tolerance_ns=round(rig.analysis.clock_sync_tolerance_ms * 1e6),
        keep_samples=_zero_unstated(rig) and bool(located),
    )
    plan, router = read_plan(probe, rig, [c for c, _, _ in located] if cameras else [])
    clouds = None if plan.cloud is None else CloudFeeder(scanner, plan.cloud)
    feed = scanner.feed if clouds is None else clouds.feed
    items = iter_items(probe.log, plan, jobs, check_crc=check_crc, meanwhile=_meanwhile(meanwhile))
    for kind, topic, payload in items:
        if kind == "lidar":
            feed(payload)
        else:
            router.feed(kind, topic, payload)
    scan = scanner.finish() if clouds is None else clouds.finish()
    warnings.extend([] if clouds is None else clouds.notes)
    if scan.packets == 0:
        raise no_packets_error(probe.log, lidar_cfg.topic)  # names a cut or damage it saw
    warnings.extend(router.finish())
    tables = [router.builders[c.name].build() for c, _, _ in located] if cameras else []
    return scanner, scan, tables


def _zero_unstated(rig: Rig) -> bool:
    """True when the rig leaves the zero-crossing azimuth to the audit's guess."""
    return "zero_azimuth_deg" not in rig.lidar.model_fields_set


def _trigger_packets_ns(tables: list[CameraTables]) -> NDArray[np.int64]:
    """Every camera's trigger packet stamps (host clock), those recorded (> 0) only."""
    found = [np.asarray(t.triggers["lidar_packet_ns"], dtype=np.int64) for t in tables]
    packets = np.concatenate(found) if found else np.empty(0, np.int64)
    return packets[packets > 0]


def _zero_from_triggers(
    rig: Rig, scanner: LidarScanner, scan: LidarScan, tables: list[CameraTables]
) -> tuple[Rig, LidarScan, str | None]:
    """The rig with the zero azimuth guessed from the trigger packets, the revolutions
    tracked again from it (where the scanner kept every sample; else the scan as it was,
    for the caller to read again), and the note saying so (the rig and scan as they
    were, and None, where no trigger packet lies among the kept packets)."""
    from syncaudit.audit.zero_guess import guess_zero_azimuth

    offset = _clock_offset(scan, tables, [])
    packets = _trigger_packets_ns(tables)
    guess = guess_zero_azimuth(
        scanner.packet_azimuth_deg(packets - offset),
        packets_per_revolution=scan.packets_per_revolution,
        azimuth_increases=rig.lidar.azimuth_increases,
    )
    if guess is None:
        return rig, scan, None
    lidar = rig.lidar.model_copy(update={"zero_azimuth_deg": guess.zero_azimuth_deg})
    retracked = scanner.retracked(lidar.zero_azimuth_deg) if scanner.kept_all else scan
    return rig.model_copy(update={"lidar": lidar}), retracked, guess.note


def _zero_warning(
    rig: Rig, scan: LidarScan, tables: list[CameraTables], offset_ns: int
) -> list[str]:
    """Once for the LiDAR: every camera's trigger packets against the rig's zero crossings."""
    from syncaudit.analysis.pairing import trigger_turn_fraction
    from syncaudit.audit.zero_guess import zero_mismatch_warning

    zero_host = scan.revolutions.zero_crossing_sensor_ns + offset_ns
    fraction = trigger_turn_fraction(zero_host, np.sort(_trigger_packets_ns(tables)))
    said = zero_mismatch_warning(
        fraction, rig.lidar.zero_azimuth_deg, azimuth_increases=rig.lidar.azimuth_increases
    )
    return [] if said is None else [said]


def _clock_offset(scan: LidarScan, tables: list[CameraTables], warnings: list[str]) -> int:
    """Host minus sensor clock from every camera's triggers (a property of the LiDAR)."""
    from syncaudit.analysis.offset import host_offset_ns

    packet, driver = [], []
    for t in tables:
        pkt = np.asarray(t.triggers["lidar_packet_ns"], dtype=np.int64)
        drv = np.asarray(t.triggers["lidar_driver_ns"], dtype=np.int64)
        # Missing (MISSING, the int64 minimum) or 0 (the driver left it unset): no packet.
        both = pkt > 0
        packet.append(pkt[both])
        if (drv[both] != MISSING).all():
            driver.append(drv[both])
    packet_ns = np.concatenate(packet) if packet else np.empty(0, np.int64)
    driver_ns = np.concatenate(driver) if len(driver) == len(packet) and driver else packet_ns[:0]
    offset, how = host_offset_ns(scan, packet_ns, driver_ns)
    if scan.clock is not None and not scan.clock.synchronised:
        warnings.append(
            f"LiDAR clock not synchronised with the host: host minus sensor {offset / 1e9:+.6f} s "
            f"({how}); t1 reported as spread above the minimum"
        )
    return offset


def _missing(log: LogReader, cam: CameraConfig, tables: CameraTables) -> list[str]:
    """What one camera's log lacks."""
    checks = (
        (
            f"image topic {cam.image_topic} is not in the log"
            if cam.image_topic
            else "no image topic (set image_topic in the rig)",
            cam.image_topic in log.topics if cam.image_topic else False,
        ),
        ("no exposure metadata", tables.exposure_source is not None),
        ("no trigger records", tables.trigger_source is not None),
    )
    return [f"camera {cam.name}: {what}" for what, present in checks if not present]


def _audit(
    probe: LogProbe,
    rig: Rig,
    guessed: list[str],
    jobs: int,
    check_crc: bool,
    meanwhile: Callable[[], object] | None = None,
) -> AuditResult:
    """Check the rig, place the cameras, read the log once, then judge what was read."""
    # Camera topics in encodings that cannot be read are dropped (warned); see rig_check.
    rig, warnings = check_rig_against_log(probe, rig)
    located = _locate_cameras(probe, rig, warnings)
    scanner, scan, all_tables = _read(
        probe, rig, located, jobs=jobs, check_crc=check_crc, warnings=warnings, meanwhile=meanwhile
    )
    warnings.extend(w for tables in all_tables for w in tables.warnings)  # damaged, skipped
    if scanner.keep_samples:
        rig, scan, note = _zero_from_triggers(rig, scanner, scan, all_tables)
        guessed = guessed if note is None else [*guessed, note]
        if note is not None and not scanner.kept_all:
            # A long log: its samples were not all kept (memory stays bounded); its
            # revolutions are found again by reading its LiDAR once more with the guessed
            # zero (the cameras' tables are kept from the first pass).
            _, scan, _ = _read(
                probe, rig, located, jobs=jobs, check_crc=check_crc, warnings=[], cameras=False
            )
    warnings.extend(scan.warnings)
    missing = _missing_inputs(rig, scan)
    offset = _clock_offset(scan, all_tables, warnings)
    warnings.extend(_zero_warning(rig, scan, all_tables, offset))
    cameras = _analyse_cameras(
        probe.log, rig, scan, located, all_tables, offset, missing, jobs=jobs
    )
    warnings.extend(_floor_warnings(rig, cameras))
    from syncaudit.audit.trigger_design import add_designs

    phase_lock = add_designs(
        rig,
        scan,
        [cam for cam, _, _ in located],
        all_tables,
        cameras,
        offset_ns=offset,
        start_ns=probe.log.summary.start_ns,
        log=probe.log,
    )
    warnings.extend(lidar_warnings(lidar_row(scan)))
    warnings.extend(w.message for w in probe.log.warnings)
    return AuditResult(
        path=probe.log.summary.path,
        container=probe.log.summary.container,
        duration_s=probe.log.summary.duration_s,
        rig=rig,
        lidar=lidar_row(scan, offset_ns=offset),
        clock_offset_ns=offset,
        cameras=cameras,
        missing=missing,
        guessed=guessed,
        warnings=warnings,
        start_ns=probe.log.summary.start_ns,
        revolutions=scan.revolutions,
        health=log_health(probe.log.warnings, warnings),
        phase_lock=phase_lock,
    )


def _missing_inputs(rig: Rig, scan: LidarScan) -> list[str]:
    """What the whole rig lacks: any camera topic, a complete LiDAR revolution."""
    missing: list[str] = []
    if not rig.cameras:
        missing.append("no camera topics: images, exposure metadata and triggers are all missing")
    if scan.revolutions.count < MIN_ZERO_CROSSINGS:
        missing.append(
            f"LiDAR topic {rig.lidar.topic}: {_no_revolution(scan.revolutions.count, scan.packets)}"
        )
    return missing


def _controller_config(rig: Rig) -> ControllerConfig:
    """The delay controller the rig runs, for replaying it over each camera's frames."""
    from syncaudit.analysis.controller import ControllerConfig

    return ControllerConfig(
        window_frames=rig.analysis.window_frames,
        mean_error_threshold_ns=round(rig.thresholds.error_mean_us * 1e3),
        variance_threshold_ns2=rig.thresholds.error_var_us2 * 1e6,
        mode=rig.analysis.correction,
        min_frames=rig.analysis.window_frames,
    )


def _analyse_cameras(
    log: LogReader,
    rig: Rig,
    scan: LidarScan,
    located: list[Located],
    all_tables: list[CameraTables],
    offset_ns: int,
    missing: list[str],
    jobs: int = 1,
) -> list[CameraAudit]:
    """Each placed camera's synchronisation and its replayed controllers; what each camera's
    log lacks is added to `missing`. Cameras are independent: with `jobs` > 1 and forking
    available, forked workers analyse them side by side (the same result, in camera order)."""
    for (cam, _, _), tables in zip(located, all_tables, strict=True):
        missing.extend(_missing(log, cam, tables))
    job = _CameraJob(rig, scan, located, all_tables, offset_ns)
    indexes = list(range(len(located)))
    if jobs < 2 or len(located) < 2 or "fork" not in multiprocessing.get_all_start_methods():
        return [job.audit(i) for i in indexes]
    token = f"cameras#{next(_camera_tokens)}"
    _CAMERA_JOBS[token] = job
    try:
        context = multiprocessing.get_context("fork")
        with worker_pool(
            min(jobs, len(located)),
            context,
            label=f"{log.summary.path}: a camera analysis process",
        ) as pool:
            return list(pool.map(_audit_camera, [token] * len(indexes), indexes))
    finally:
        _CAMERA_JOBS.pop(token, None)


@dataclass(frozen=True, slots=True)
class _CameraJob:
    """What each camera's analysis reads (forked workers inherit it: nothing is pickled
    but the camera's index and its result)."""

    rig: Rig
    scan: LidarScan
    located: list[Located]
    all_tables: list[CameraTables]
    offset_ns: int

    def audit(self, index: int) -> CameraAudit:
        """One camera's synchronisation (Eq. 1-6), the replayed controllers and the advice."""
        # Imported only now: `_read` has them imported while workers read.
        from syncaudit.analysis.advice import advise_camera
        from syncaudit.analysis.replay import replay_controller
        from syncaudit.analysis.sync import analyze_camera

        rig = self.rig
        cam, azimuth, source = self.located[index]
        sync = analyze_camera(
            self.scan,
            self.all_tables[index],
            camera=cam,
            target_index=index,
            camera_azimuth_deg=azimuth,
            offset_ns=self.offset_ns,
            lidar=rig.lidar,
            analysis=rig.analysis,
            thresholds=rig.thresholds,
        )
        replay = replay_controller(sync.table, _controller_config(rig))
        advice = advise_camera(sync.table, replay)
        # Judged against what a correction can change; the CSV shows the advised delays.
        sync.correctable = not advice.at_floor
        sync.table = sync.table.with_columns({"advised_delay_ns": advice.advised_delay_ns})
        return CameraAudit(sync, azimuth, source, replay, advice)


_CAMERA_JOBS: dict[str, _CameraJob] = {}
"""The analysis each running camera pool serves, by token (forked workers look it up)."""
_camera_tokens = itertools.count()


def _audit_camera(token: str, index: int) -> CameraAudit:
    """A forked worker's task: camera `index` of the job `token` names."""
    return _CAMERA_JOBS[token].audit(index)


def _floor_warnings(rig: Rig, cameras: list[CameraAudit]) -> list[str]:
    """One warning naming the cameras whose floor lies above the Eq. 5 limit."""
    limit_us = rig.thresholds.error_mean_us
    below = [
        f"{c.sync.camera} {c.advice.floor.error_mean_ns / 1e3:.0f} us"
        for c in cameras
        if c.advice.floor.error_mean_ns > limit_us * 1e3
    ]
    if not below:
        return []
    return [
        f"thresholds.error_mean_us {limit_us:g} is below what this trigger design can reach "
        f"(floor: {', '.join(below)}): such a camera is judged only on what a correction "
        "can change"
    ]
