"""Part A of the method on extracted columns: Eq. 1-6 per camera, vectorised.

Inputs are the reduced LiDAR timing (revolutions with the crossing time of each camera
centre) and one camera's frame and trigger tables. Per frame it finds the revolution
the frame belongs to, `t_estimated` (beam at the camera centre, host clock), `t_l`
(mid-exposure), the signed and absolute error, the latencies t1..t4 from the trigger
checkpoints, the running exposure average (Eq. 3) and the delay Eq. 2 prescribes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from syncaudit.analysis.pairing import (
    PAIR_TOLERANCE_NS,
    PHASE_FROM_TRACKER,
    PHASE_FROM_TRIGGER,
    RevolutionPairing,
    pair_frames,
    pair_revolutions,
    pair_triggers,
)
from syncaudit.analysis.stamps import (
    MISSING_NS,
    delta_ns,
    present,
    stamps_ns,
    values_ns,
)
from syncaudit.analysis.stats import error_mean, error_variance, rolling_mean, rolling_variance
from syncaudit.columns.camera import CAMERA_EXPOSURE, CameraTables
from syncaudit.columns.frame_table import FRAME_TABLE_DTYPES
from syncaudit.columns.lidar import ClockReport, LidarScan
from syncaudit.columns.table import Table, str_column
from syncaudit.rig import AnalysisConfig, CameraConfig, LidarConfig, Thresholds
from syncaudit.units import finite_or_none, ns_to_us

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["CameraSync", "LatencyStats", "analyze_camera", "pair_triggers", "theta_deg"]

FULL_TURN_DEG = 360.0
LATENCIES = ("t1", "t2", "t3", "t4")


@dataclass(frozen=True, slots=True)
class LatencyStats:
    """One latency of the trigger chain: observed in the log, assumed, or unknown."""

    status: str
    """'observed', 'assumed' or 'not observed'."""
    mean_ns: float
    p50_ns: float
    p99_ns: float
    count: int

    def to_dict(self) -> dict[str, Any]:
        """JSON form in microseconds."""
        return {
            "status": self.status,
            "mean_us": ns_to_us(self.mean_ns),
            "p50_us": ns_to_us(self.p50_ns),
            "p99_us": ns_to_us(self.p99_ns),
            "count": self.count,
        }


@dataclass(slots=True)
class CameraSync:
    """The audit of one camera."""

    camera: str
    theta_deg: float
    omega_deg_s: float
    t_rotate_ns: float
    packet_phase_ns: float
    """Mean time from the stamp of the packet the trigger fired from to the zero crossing
    of the frame's revolution."""
    packet_phase_source: str
    """Which packet the phases were measured from: 'trigger packet' (the packet the
    trigger names), 'tracker zero packet' (the trigger names none), 'mixed: ...' or 'none'."""
    latencies: dict[str, LatencyStats]
    t5_mean_ns: float
    delay_applied_ns: float
    delay_recommended_ns: float
    """Eq. 2 with the whole log's averages, from the trigger packet's stamp."""
    delay_from_error_ns: float
    """Cross-check: applied delay minus mean signed error."""
    frames_total: int
    frames_paired: int
    unpaired: dict[str, int]
    error_signed_mean_ns: float
    error_mean_ns: float
    error_var_ns2: float
    error_p99_ns: float
    error_max_ns: float
    rolling_mean_max_ns: float
    rolling_var_max_ns2: float
    mean_exceeded: bool
    var_exceeded: bool
    table: Table = field(repr=False)
    """The per-frame table (FRAME_TABLE_DTYPES); `frames` hands it out as a DataFrame."""
    judged: bool = True
    """Whether enough frames paired for Eq. 5/6 to be a verdict (rig thresholds)."""
    not_judged_reason: str | None = None
    optional: bool = False
    """The rig marks the camera optional: not judged does not fail the audit."""
    warnings: list[str] = field(default_factory=list)
    trigger_pairing: str = "none"
    """How frames were paired with their triggers: 'sequence number', 'time' or 'none' (no
    triggers); where by time although numbers were recorded, a warning says why."""
    correctable: bool = True
    """Whether a replayed correction lowers Eq. 5 (set by the advice; False: at its floor)."""
    _frames: pd.DataFrame | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def frames(self) -> pd.DataFrame:
        """The per-frame table (what --csv writes): stamps Int64, differences float64.

        Built on first use (imports pandas): an audit writing only JSON never needs it.
        """
        if self._frames is None:
            self._frames = self.table.to_pandas(FRAME_TABLE_DTYPES)
        return self._frames

    @property
    def needs_correction(self) -> bool:
        """Whether Eq. 5 or Eq. 6 crossed its threshold over the whole log and a correction
        can change that (`correctable`: the camera is not at its floor)."""
        return (self.mean_exceeded or self.var_exceeded) and self.correctable

    @property
    def verdict(self) -> str:
        """'pass', 'fail' (a threshold crossed) or 'not judged' (too few paired frames)."""
        if not self.judged:
            return "not judged"
        return "fail" if self.needs_correction else "pass"

    def to_dict(self) -> dict[str, Any]:
        """JSON form (times in microseconds, see schemas/audit.schema.json)."""
        return {
            "camera": self.camera,
            "theta_deg": finite_or_none(self.theta_deg),
            "omega_deg_s": finite_or_none(self.omega_deg_s),
            "t_rotate_us": ns_to_us(self.t_rotate_ns),
            "packet_phase_us": ns_to_us(self.packet_phase_ns),
            "packet_phase_source": self.packet_phase_source,
            "trigger_pairing": self.trigger_pairing,
            "latencies": {k: v.to_dict() for k, v in self.latencies.items()},
            "t5_mean_us": ns_to_us(self.t5_mean_ns),
            "delay_applied_us": ns_to_us(self.delay_applied_ns),
            "delay_recommended_us": ns_to_us(self.delay_recommended_ns),
            "delay_from_error_us": ns_to_us(self.delay_from_error_ns),
            "frames_total": self.frames_total,
            "frames_paired": self.frames_paired,
            "unpaired": dict(self.unpaired),
            "error_signed_mean_us": ns_to_us(self.error_signed_mean_ns),
            "error_mean_us": ns_to_us(self.error_mean_ns),
            "error_var_us2": finite_or_none(self.error_var_ns2 / 1e6),
            "error_p99_us": ns_to_us(self.error_p99_ns),
            "error_max_us": ns_to_us(self.error_max_ns),
            "rolling_mean_max_us": ns_to_us(self.rolling_mean_max_ns),
            "rolling_var_max_us2": finite_or_none(self.rolling_var_max_ns2 / 1e6),
            "mean_threshold_exceeded": self.mean_exceeded,
            "var_threshold_exceeded": self.var_exceeded,
            "needs_correction": self.needs_correction,
            "judged": self.judged,
            "not_judged_reason": self.not_judged_reason,
            "optional": self.optional,
            "verdict": self.verdict,
            "warnings": list(self.warnings),
        }


def theta_deg(camera_azimuth_deg: float, zero_azimuth_deg: float, azimuth_increases: bool) -> float:
    """Angle from the zero crossing to the camera centre, in the direction of rotation."""
    delta = camera_azimuth_deg - zero_azimuth_deg
    return (delta if azimuth_increases else -delta) % FULL_TURN_DEG


@dataclass(frozen=True, slots=True)
class _Rotation:
    """Eq. 1 for one camera: theta, the mean angular velocity, t_rotate."""

    theta_deg: float
    omega_deg_s: float
    t_rotate_ns: float

    @property
    def period_ns(self) -> float:
        """One revolution (NaN where the rate is unknown)."""
        return 1e9 * FULL_TURN_DEG / self.omega_deg_s if self.omega_deg_s else math.nan


def _rotation(scan: LidarScan, camera_azimuth_deg: float, lidar: LidarConfig) -> _Rotation:
    """Eq. 1 from the camera azimuth and the revolutions' measured rate."""
    theta = theta_deg(camera_azimuth_deg, lidar.zero_azimuth_deg, lidar.azimuth_increases)
    omega = scan.revolutions.omega_deg_s
    omega = omega[np.isfinite(omega)]
    omega_mean = float(omega.mean()) if omega.size else math.nan
    t_rotate = theta / omega_mean * 1e9 if omega_mean else math.nan
    return _Rotation(theta, omega_mean, t_rotate)


def _start_after_trigger(
    frames: Table, camera: CameraConfig, analysis: AnalysisConfig
) -> tuple[Table, str | None]:
    """Exposure starts of frames stamped at their trigger (246), moved on by t4 to 248.

    With `stamp: trigger` the header stamp is when the trigger reached the camera; the
    exposure starts t4 later. t4 is each frame's own where its trigger records 248 and
    246, else `analysis.assumed_t4_us`; without either the start stays at the trigger (t_l
    early by t4) and the warning says so. Exposure records stating their start
    (CameraExposure) are left alone.
    """
    if camera.stamp != "trigger" or frames.empty:
        return frames, None
    derived = frames["source"] != CAMERA_EXPOSURE  # None (no type) counts as derived
    start = stamps_ns(frames, "exposure_start_ns")
    derived &= present(start)
    if not derived.any():
        return frames, None
    t4 = delta_ns(
        stamps_ns(frames, "trig_exposure_start_ns"), stamps_ns(frames, "trig_camera_sensor_ns")
    )
    if analysis.assumed_t4_us is not None:
        t4 = np.where(np.isfinite(t4), t4, analysis.assumed_t4_us * 1e3)
    known = derived & np.isfinite(t4)
    moved = np.where(known, start + np.rint(np.nan_to_num(t4)).astype(np.int64), start)
    out = frames.with_columns({"exposure_start_ns": moved})
    unknown = int(np.sum(derived & ~known))
    if not unknown:
        return out, None
    return out, (
        f"{unknown} frames stamped at the trigger (246) without t4 (no trigger record of 248, "
        "no analysis.assumed_t4_us): exposure start taken at the trigger, t_l early by t4"
    )


def _t_l_ns(frames: Table) -> NDArray[np.int64]:
    """Mid-exposure per frame, exposure start + t5_i // 2, int64 (`MISSING_NS` if unknown)."""
    start = stamps_ns(frames, "exposure_start_ns")
    duration = stamps_ns(frames, "exposure_duration_ns")
    ok = present(start) & present(duration)
    return np.where(ok, start + np.where(ok, duration, 0) // 2, MISSING_NS)


@dataclass(frozen=True, slots=True)
class _Errors:
    """Eq. 4 per frame, signed, and why frames stayed unpaired."""

    signed_ns: NDArray[np.float64]
    """t_l - t_estimated where paired, else NaN."""
    paired: NDArray[np.bool_]
    unpaired: dict[str, int]


def _errors(
    t_l_ns: NDArray[np.int64], t_estimated_ns: NDArray[np.int64], *, period_ns: float
) -> _Errors:
    """Signed error per frame; beyond a quarter revolution a frame is not paired."""
    signed = delta_ns(t_l_ns, t_estimated_ns)
    quarter = 0.25 * period_ns if math.isfinite(period_ns) else math.inf
    has_t_l = present(t_l_ns)
    far = np.isfinite(signed) & (np.abs(np.nan_to_num(signed)) > quarter)
    unpaired = {
        "no exposure metadata": int(np.sum(~has_t_l)),
        "no LiDAR revolution": int(np.sum(has_t_l & ~present(t_estimated_ns))),
        "error beyond a quarter revolution": int(np.sum(far)),
    }
    paired = np.isfinite(signed) & ~far
    return _Errors(
        np.where(paired, signed, np.nan), paired, {k: v for k, v in unpaired.items() if v}
    )


def _latency(
    values: NDArray[np.float64], assumed_us: float | None
) -> tuple[NDArray[np.float64], LatencyStats]:
    finite = values[np.isfinite(values)]
    if finite.size:
        return values, LatencyStats(
            "observed",
            float(finite.mean()),
            float(np.percentile(finite, 50)),
            float(np.percentile(finite, 99)),
            int(finite.size),
        )
    if assumed_us is not None:
        v = assumed_us * 1e3
        return np.full(values.shape, v), LatencyStats("assumed", v, v, v, 0)
    return values, LatencyStats("not observed", math.nan, math.nan, math.nan, 0)


def _latencies(
    frames: Table, clock: ClockReport | None, analysis: AnalysisConfig
) -> tuple[dict[str, NDArray[np.float64]], dict[str, LatencyStats]]:
    """t1..t4 per frame from the trigger checkpoints (t3 without the applied delay).

    Where the log does not record a latency the rig's assumption stands in; t1 falls back
    to the LiDAR clock's packet statistics when no trigger records its packet.
    """
    packet = stamps_ns(frames, "trig_lidar_packet_ns")
    driver = stamps_ns(frames, "trig_lidar_driver_ns")
    cam_driver = stamps_ns(frames, "trig_camera_driver_ns")
    cam_sensor = stamps_ns(frames, "trig_camera_sensor_ns")
    applied = values_ns(frames, "trig_applied_delay_ns")
    raw = {
        "t1": delta_ns(driver, packet),
        "t2": delta_ns(cam_driver, driver),
        "t3": delta_ns(cam_sensor, cam_driver) - applied,
        "t4": delta_ns(stamps_ns(frames, "trig_exposure_start_ns"), cam_sensor),
    }
    if not np.isfinite(raw["t1"]).any() and clock is not None:
        raw["t1"] = np.full(len(frames), clock.t1_mean_ns)
    assumed = {
        "t1": None,
        "t2": analysis.assumed_t2_us,
        "t3": analysis.assumed_t3_us,
        "t4": analysis.assumed_t4_us,
    }
    lat: dict[str, NDArray[np.float64]] = {}
    stats: dict[str, LatencyStats] = {}
    for name in LATENCIES:
        lat[name], stats[name] = _latency(raw[name], assumed[name])
    if clock is not None and not present(packet).any():
        c = clock
        stats["t1"] = LatencyStats("observed", c.t1_mean_ns, c.t1_p50_ns, c.t1_p99_ns, c.packets)
    return lat, stats


@dataclass(frozen=True, slots=True)
class _DelayTerms:
    """Eq. 2 and Eq. 3: per frame and over the whole log."""

    t5_avg_ns: NDArray[np.float64]
    """Eq. 3 running exposure average per frame."""
    t_sleep_ns: NDArray[np.float64]
    """Eq. 2 per frame, from the trigger packet's stamp."""
    t5_mean_ns: float
    phase_mean_ns: float
    recommended_ns: float
    """Eq. 2 with the whole log's averages."""
    applied_mean_ns: float


def _delay_terms(
    rotation: _Rotation,
    revolutions: RevolutionPairing,
    lat: dict[str, NDArray[np.float64]],
    stats: dict[str, LatencyStats],
    duration_ns: NDArray[np.float64],
    applied_ns: NDArray[np.float64],
    *,
    window_frames: int,
) -> _DelayTerms:
    """Eq. 2 from the packet the trigger fired from: t_rotate + its phase - chain - t5/2."""
    phase = revolutions.packet_phase_ns
    t5_avg = rolling_mean(duration_ns, window_frames)
    chain = lat["t1"] + lat["t2"] + lat["t3"] + lat["t4"]
    t_sleep = rotation.t_rotate_ns + phase - (chain + t5_avg / 2.0)
    phase_mean = float(np.nanmean(phase)) if np.isfinite(phase).any() else 0.0
    means = [v.mean_ns if math.isfinite(v.mean_ns) else math.nan for v in stats.values()]
    t5_mean = float(np.nanmean(duration_ns)) if np.isfinite(duration_ns).any() else math.nan
    recommended = rotation.t_rotate_ns + phase_mean - (sum(means) + t5_mean / 2.0)
    applied_mean = float(np.nanmean(applied_ns)) if np.isfinite(applied_ns).any() else math.nan
    return _DelayTerms(t5_avg, t_sleep, t5_mean, phase_mean, recommended, applied_mean)


def _judgement(paired: int, total: int, thresholds: Thresholds) -> str | None:
    """Why a camera with `paired` of `total` frames paired is not judged (None: it is)."""
    need = max(thresholds.min_paired_frames, math.ceil(thresholds.min_paired_fraction * total))
    if paired >= need and total:
        return None
    return (
        f"only {paired} of {total} frames paired with the LiDAR (a verdict needs at least "
        f"{thresholds.min_paired_frames} and {thresholds.min_paired_fraction:.0%})"
    )


def _frame_table(
    camera: str,
    frames: Table,
    t_l_ns: NDArray[np.int64],
    revolutions: RevolutionPairing,
    errors: _Errors,
    lat: dict[str, NDArray[np.float64]],
    delay: _DelayTerms,
    applied_ns: NDArray[np.float64],
    *,
    window_frames: int,
) -> Table:
    """The per-frame table (what --csv writes), columns as FRAME_TABLE_DTYPES."""
    t_error = np.abs(errors.signed_ns)
    masked = np.where(errors.paired, t_error, np.nan)
    source = [
        (PHASE_FROM_TRIGGER if trig else PHASE_FROM_TRACKER) if rev >= 0 else None
        for rev, trig in zip(
            revolutions.revolution.tolist(), revolutions.phase_from_trigger.tolist(), strict=True
        )
    ]
    columns = {
        "camera": str_column([camera] * len(frames)),
        "frame_sequence": frames["frame_sequence"],
        "exposure_start_ns": frames["exposure_start_ns"],
        "exposure_duration_ns": frames["exposure_duration_ns"],
        "t_l_ns": t_l_ns,
        "t_estimated_ns": revolutions.t_estimated_ns,
        "error_signed_ns": errors.signed_ns,
        "t_error_ns": t_error,
        "paired": errors.paired,
        "revolution": revolutions.revolution,
        "revolution_start_ns": revolutions.revolution_start_ns,
        "header_stamp_ns": frames["header_stamp_ns"],
        "t1_ns": lat["t1"],
        "t2_ns": lat["t2"],
        "t3_ns": lat["t3"],
        "t4_ns": lat["t4"],
        "t5_avg_ns": delay.t5_avg_ns,
        "t_rotate_ns": revolutions.t_rotate_ns,
        "packet_phase_ns": revolutions.packet_phase_ns,
        "packet_phase_source": str_column(source),
        "t_sleep_ns": delay.t_sleep_ns,
        "applied_delay_ns": applied_ns,
        "rolling_error_mean_ns": rolling_mean(masked, window_frames),
        "rolling_error_var_ns2": rolling_variance(masked, window_frames),
        # The recommended action's delay per frame: filled by `analysis.advice`.
        "advised_delay_ns": np.full(len(frames), np.nan),
    }
    return Table(columns, len(frames))


def _camera_warnings(frames: Table, stats: dict[str, LatencyStats]) -> list[str]:
    """What the log lacks for this camera, as warnings."""
    warnings: list[str] = []
    if frames.empty:
        warnings.append("no frames: nothing to pair with the LiDAR")
    elif not present(stamps_ns(frames, "exposure_duration_ns")).any():
        warnings.append("no exposure metadata: t5 and t_l unknown (set assumed_exposure_us)")
    for name in LATENCIES:
        if stats[name].status == "not observed":
            warnings.append(f"{name} not observed in the log (set analysis.assumed_{name}_us)")
    return warnings


def _nanmax(values: NDArray[np.float64]) -> float:
    return float(np.nanmax(values)) if np.isfinite(values).any() else math.nan


def analyze_camera(
    scan: LidarScan,
    tables: CameraTables,
    *,
    camera: CameraConfig,
    target_index: int,
    camera_azimuth_deg: float,
    offset_ns: int,
    lidar: LidarConfig,
    analysis: AnalysisConfig,
    thresholds: Thresholds,
) -> CameraSync:
    """Eq. 1-6 for one camera over the whole log; `offset_ns` is host minus sensor clock.

    `target_index` is the camera's column in the revolutions' target crossings.
    """
    rotation = _rotation(scan, camera_azimuth_deg, lidar)
    trigger_pairing = pair_frames(
        tables.frames,
        tables.triggers,
        trigger_stamped=camera.stamp == "trigger",
        counters=None
        if tables.frame_counter is None or tables.trigger_counter is None
        else (tables.frame_counter, tables.trigger_counter),
    )
    frames, pairing_warning = trigger_pairing.frames, trigger_pairing.warning
    frames, t4_warning = _start_after_trigger(frames, camera, analysis)
    t_l = _t_l_ns(frames)
    period = rotation.period_ns
    revolutions = pair_revolutions(
        frames,
        scan.revolutions,
        t_l,
        target_index=target_index,
        offset_ns=offset_ns,
        max_gap_ns=0.5 * period if math.isfinite(period) else PAIR_TOLERANCE_NS,
        zero_from_triggers="zero_azimuth_deg" not in lidar.model_fields_set,
    )
    errors = _errors(t_l, revolutions.t_estimated_ns, period_ns=period)
    lat, stats = _latencies(frames, scan.clock, analysis)
    duration = values_ns(frames, "exposure_duration_ns")
    applied = values_ns(frames, "trig_applied_delay_ns")
    delay = _delay_terms(
        rotation, revolutions, lat, stats, duration, applied, window_frames=analysis.window_frames
    )
    table = _frame_table(
        camera.name,
        frames,
        t_l,
        revolutions,
        errors,
        lat,
        delay,
        applied,
        window_frames=analysis.window_frames,
    )
    warnings = _camera_warnings(frames, stats)
    if pairing_warning:
        warnings.insert(0, pairing_warning)
    if t4_warning:
        warnings.append(t4_warning)
    return _camera_sync(
        camera,
        rotation,
        revolutions,
        errors,
        stats,
        delay,
        table,
        warnings,
        thresholds,
        shared_topic_notes=tables.shared_topic_notes,
        trigger_pairing=trigger_pairing.method,
    )


def _camera_sync(
    camera: CameraConfig,
    rotation: _Rotation,
    revolutions: RevolutionPairing,
    errors: _Errors,
    stats: dict[str, LatencyStats],
    delay: _DelayTerms,
    table: Table,
    warnings: list[str],
    thresholds: Thresholds,
    *,
    shared_topic_notes: tuple[str, ...] = (),
    trigger_pairing: str = "none",
) -> CameraSync:
    """Eq. 5/6 over the paired frames, the thresholds and the judgement, as a CameraSync.

    A camera not judged because a topic it shares with others gave it nothing says so
    first (`shared_topic_notes`), then the counts.
    """
    s = errors.signed_ns[errors.paired]
    e = np.abs(s)
    mean_e, var_e = error_mean(e), error_variance(e)
    paired = int(errors.paired.sum())
    reason = _judgement(paired, len(table), thresholds)
    if reason is not None and shared_topic_notes:
        reason = f"{'; '.join(shared_topic_notes)} ({reason})"
    return CameraSync(
        camera=camera.name,
        theta_deg=rotation.theta_deg,
        omega_deg_s=rotation.omega_deg_s,
        t_rotate_ns=rotation.t_rotate_ns,
        packet_phase_ns=delay.phase_mean_ns,
        packet_phase_source=revolutions.phase_source(),
        latencies=stats,
        t5_mean_ns=delay.t5_mean_ns,
        delay_applied_ns=delay.applied_mean_ns,
        delay_recommended_ns=delay.recommended_ns,
        delay_from_error_ns=delay.applied_mean_ns - float(s.mean()) if s.size else math.nan,
        frames_total=len(table),
        frames_paired=paired,
        unpaired=errors.unpaired,
        error_signed_mean_ns=float(s.mean()) if s.size else math.nan,
        error_mean_ns=mean_e,
        error_var_ns2=var_e,
        error_p99_ns=float(np.percentile(e, 99)) if e.size else math.nan,
        error_max_ns=float(e.max()) if e.size else math.nan,
        rolling_mean_max_ns=_nanmax(table["rolling_error_mean_ns"]),
        rolling_var_max_ns2=_nanmax(table["rolling_error_var_ns2"]),
        mean_exceeded=bool(mean_e > thresholds.error_mean_us * 1e3),
        var_exceeded=bool(var_e > thresholds.error_var_us2 * 1e6),
        table=table,
        judged=reason is None,
        not_judged_reason=reason,
        optional=camera.optional,
        warnings=warnings,
        trigger_pairing=trigger_pairing,
    )
