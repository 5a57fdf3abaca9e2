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
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from syncaudit.analysis.stats import error_mean, error_variance, rolling_mean, rolling_variance
from syncaudit.camera.extract import CameraTables
from syncaudit.lidar.scan import LidarScan
from syncaudit.rig import AnalysisConfig, CameraConfig, Thresholds
from syncaudit.units import finite_or_none, ns_to_us

FULL_TURN_DEG = 360.0
PAIR_TOLERANCE_NS = 50_000_000
"""A trigger belongs to a frame when it precedes the exposure by less than this."""
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
    """Mean time from the trigger packet's stamp to the zero crossing it carries."""
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
    frames: pd.DataFrame = field(repr=False)
    warnings: list[str] = field(default_factory=list)

    @property
    def needs_correction(self) -> bool:
        """Whether Eq. 5 or Eq. 6 crossed its threshold over the whole log."""
        return self.mean_exceeded or self.var_exceeded

    def to_dict(self) -> dict[str, Any]:
        """JSON form (times in microseconds, see schemas/audit.schema.json)."""
        return {
            "camera": self.camera,
            "theta_deg": finite_or_none(self.theta_deg),
            "omega_deg_s": finite_or_none(self.omega_deg_s),
            "t_rotate_us": ns_to_us(self.t_rotate_ns),
            "packet_phase_us": ns_to_us(self.packet_phase_ns),
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
            "warnings": list(self.warnings),
        }


def theta_deg(camera_azimuth_deg: float, zero_azimuth_deg: float, azimuth_increases: bool) -> float:
    """Angle from the zero crossing to the camera centre, in the direction of rotation."""
    delta = camera_azimuth_deg - zero_azimuth_deg
    return (delta if azimuth_increases else -delta) % FULL_TURN_DEG


def host_offset_ns(scan: LidarScan, packet_ns: NDArray[np.int64]) -> tuple[int, str]:
    """Host minus sensor clock: 0 when synchronised, else from triggers or the clock floor.

    `packet_ns` are the triggers' checkpoint-240 stamps (the zero-crossing packet in host
    time) of every camera; it is a property of the LiDAR, computed once per log.
    """
    clock = scan.clock
    if clock is None or clock.synchronised:
        return 0, "synchronised"
    packet = packet_ns
    zero_pkt = scan.revolutions.zero_packet_sensor_ns
    if packet.size and zero_pkt.size:
        # The trigger's 240 stamp is the zero-crossing packet in host time: pair by the
        # floor estimate, then take the median residual as the offset.
        guess = packet - clock.offset_ns
        idx = _nearest(zero_pkt, guess)
        return int(np.median(packet - zero_pkt[idx])), "from trigger packet stamps"
    return clock.offset_ns, "minimum filter (absolute errors uncertain by the t1 floor)"


def _nearest(sorted_values: NDArray[np.int64], query: NDArray[np.int64]) -> NDArray[np.int64]:
    """Index of the nearest element of a sorted array for each query."""
    idx = np.searchsorted(sorted_values, query)
    idx = np.clip(idx, 1, max(sorted_values.size - 1, 1))
    left = sorted_values[idx - 1]
    right = sorted_values[np.minimum(idx, sorted_values.size - 1)]
    choose_left = np.abs(query - left) <= np.abs(right - query)
    return np.where(choose_left, idx - 1, idx).astype(np.int64)


def pair_triggers(frames: pd.DataFrame, triggers: pd.DataFrame) -> pd.DataFrame:
    """Frames with their trigger's checkpoints: by frame sequence, else by time."""
    checkpoint_cols = [c for c in triggers.columns if c.endswith("_ns") and c != "log_time_ns"]
    if triggers.empty:
        out = frames.copy()
        for col in checkpoint_cols:
            out[f"trig_{col}"] = pd.array([pd.NA] * len(out), dtype="Int64")
        return out
    trig = triggers[["frame_sequence", *checkpoint_cols]].add_prefix("trig_")
    if frames["frame_sequence"].notna().all() and triggers["frame_sequence"].notna().all():
        trig = trig.drop_duplicates("trig_frame_sequence", keep="last")
        merged = frames.merge(
            trig, left_on="frame_sequence", right_on="trig_frame_sequence", how="left"
        )
        return merged.drop(columns="trig_frame_sequence")
    key = (
        "trig_exposure_start_ns"
        if trig["trig_exposure_start_ns"].notna().any()
        else "trig_camera_sensor_ns"
    )
    # Frames without exposure metadata pair by their header stamp instead.
    when = frames["exposure_start_ns"].fillna(frames["header_stamp_ns"]).astype("float64")
    left = frames.assign(_t=when, _row=np.arange(len(frames)))
    timed = left.dropna(subset=["_t"]).sort_values("_t")
    right = trig.assign(_t=trig[key].astype("float64")).dropna(subset=["_t"]).sort_values("_t")
    merged = pd.merge_asof(
        timed,
        right.drop(columns="trig_frame_sequence"),
        on="_t",
        direction="backward",
        tolerance=PAIR_TOLERANCE_NS,
    )
    untimed = left[left["_t"].isna()]
    merged = pd.concat([merged, untimed], ignore_index=True).sort_values("_row")
    return merged.drop(columns=["_t", "_row"]).reset_index(drop=True)


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


def _col(df: pd.DataFrame, name: str) -> NDArray[np.float64]:
    """A column as float64 with NaN for missing values (all NaN where the column is absent)."""
    if name not in df:
        return np.full(len(df), np.nan, dtype=np.float64)
    values: NDArray[np.float64] = np.asarray(
        df[name].astype("Float64").to_numpy(dtype=np.float64, na_value=np.nan), dtype=np.float64
    )
    return values


def analyze_camera(
    scan: LidarScan,
    target_index: int,
    camera: CameraConfig,
    camera_azimuth_deg: float,
    tables: CameraTables,
    offset: int,
    zero_azimuth_deg: float,
    azimuth_increases: bool,
    analysis: AnalysisConfig,
    thresholds: Thresholds,
) -> CameraSync:
    """Eq. 1-6 for one camera over the whole log; `offset` is host minus sensor clock (ns)."""
    warnings: list[str] = []
    revs = scan.revolutions
    theta = theta_deg(camera_azimuth_deg, zero_azimuth_deg, azimuth_increases)
    omega = revs.omega_deg_s[np.isfinite(revs.omega_deg_s)]
    omega_mean = float(omega.mean()) if omega.size else math.nan
    t_rotate = theta / omega_mean * 1e9 if omega_mean else math.nan
    frames = pair_triggers(tables.frames, tables.triggers)
    n = len(frames)
    start = _col(frames, "exposure_start_ns")
    duration = _col(frames, "exposure_duration_ns")
    t_l = start + duration / 2.0

    # Revolution of each frame: the trigger's packet where recorded, else the nearest crossing.
    crossing = revs.crossing_sensor_ns[:, target_index] if revs.count else np.empty(0, np.int64)
    crossing_host = np.where(crossing >= 0, crossing + offset, -1)
    pkt = _col(frames, "trig_lidar_packet_ns")
    rev_idx = np.full(n, -1, dtype=np.int64)
    if revs.count:
        zero_host = revs.zero_packet_sensor_ns + offset
        has_pkt = np.isfinite(pkt)
        if has_pkt.any():
            q = pkt[has_pkt].astype(np.int64)
            idx = _nearest(zero_host, q)
            close = np.abs(zero_host[idx] - q) < PAIR_TOLERANCE_NS
            rev_idx[np.flatnonzero(has_pkt)[close]] = idx[close]
        no_pkt = ~has_pkt & np.isfinite(t_l)
        valid_cross = np.flatnonzero(crossing_host >= 0)
        if no_pkt.any() and valid_cross.size:
            idx = _nearest(crossing_host[valid_cross], t_l[no_pkt].astype(np.int64))
            rev_idx[no_pkt] = valid_cross[idx]
    t_est = np.full(n, np.nan)
    has_rev = rev_idx >= 0
    t_est[has_rev] = crossing_host[rev_idx[has_rev]]
    t_est[t_est < 0] = np.nan
    revolution_start = np.full(n, np.nan)
    if revs.count:
        revolution_start[has_rev] = revs.zero_crossing_sensor_ns[rev_idx[has_rev]] + offset
    packet_phase = np.full(n, np.nan)
    if revs.count:
        zc = (revs.zero_crossing_sensor_ns - revs.zero_packet_sensor_ns).astype(np.float64)
        packet_phase[has_rev] = zc[rev_idx[has_rev]]

    signed = t_l - t_est
    half_period = 0.25 * 1e9 * FULL_TURN_DEG / omega_mean if omega_mean else math.inf
    unpaired = {
        "no exposure metadata": int(np.sum(~np.isfinite(t_l))),
        "no LiDAR revolution": int(np.sum(np.isfinite(t_l) & ~np.isfinite(t_est))),
        "error beyond a quarter revolution": int(np.sum(np.abs(signed) > half_period)),
    }
    paired = np.isfinite(signed) & (np.abs(signed) <= half_period)
    signed = np.where(paired, signed, np.nan)
    t_error = np.abs(signed)

    # Latencies from the trigger checkpoints (t3 has the applied delay removed).
    applied = _col(frames, "trig_applied_delay_ns")
    raw = {
        "t1": _col(frames, "trig_lidar_driver_ns") - _col(frames, "trig_lidar_packet_ns"),
        "t2": _col(frames, "trig_camera_driver_ns") - _col(frames, "trig_lidar_driver_ns"),
        "t3": _col(frames, "trig_camera_sensor_ns")
        - _col(frames, "trig_camera_driver_ns")
        - applied,
        "t4": _col(frames, "trig_exposure_start_ns") - _col(frames, "trig_camera_sensor_ns"),
    }
    if not np.isfinite(raw["t1"]).any() and scan.clock is not None:
        raw["t1"] = np.full(n, scan.clock.t1_mean_ns)
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
    if scan.clock is not None and not np.isfinite(_col(frames, "trig_lidar_packet_ns")).any():
        c = scan.clock
        stats["t1"] = LatencyStats("observed", c.t1_mean_ns, c.t1_p50_ns, c.t1_p99_ns, c.packets)

    # Eq. 3 running exposure and Eq. 2 per frame, from the trigger packet's stamp.
    window = analysis.window_frames
    t5_avg = rolling_mean(duration, window)
    chain = lat["t1"] + lat["t2"] + lat["t3"] + lat["t4"]
    t_rotate_frame = (t_est - _col(frames, "trig_lidar_packet_ns")) - packet_phase
    t_sleep = t_rotate + packet_phase - (chain + t5_avg / 2.0)
    phase_mean = float(np.nanmean(packet_phase)) if np.isfinite(packet_phase).any() else 0.0
    means = {k: (v.mean_ns if math.isfinite(v.mean_ns) else math.nan) for k, v in stats.items()}
    t5_mean = float(np.nanmean(duration)) if np.isfinite(duration).any() else math.nan
    recommended = t_rotate + phase_mean - (sum(means.values()) + t5_mean / 2.0)
    applied_mean = float(np.nanmean(applied)) if np.isfinite(applied).any() else math.nan
    e = t_error[paired]
    s = signed[paired]
    roll_mean = rolling_mean(np.where(paired, t_error, np.nan), window)
    roll_var = rolling_variance(np.where(paired, t_error, np.nan), window)
    mean_e, var_e = error_mean(e), error_variance(e)
    thr_mean = thresholds.error_mean_us * 1e3
    thr_var = thresholds.error_var_us2 * 1e6
    table = pd.DataFrame(
        {
            "camera": camera.name,
            "frame_sequence": frames["frame_sequence"].to_numpy(),
            "exposure_start_ns": frames["exposure_start_ns"].to_numpy(),
            "exposure_duration_ns": frames["exposure_duration_ns"].to_numpy(),
            "t_l_ns": t_l,
            "t_estimated_ns": t_est,
            "error_signed_ns": signed,
            "t_error_ns": t_error,
            "paired": paired,
            "revolution": rev_idx,
            "revolution_start_ns": revolution_start,
            "header_stamp_ns": frames["header_stamp_ns"].to_numpy(),
            "t1_ns": lat["t1"],
            "t2_ns": lat["t2"],
            "t3_ns": lat["t3"],
            "t4_ns": lat["t4"],
            "t5_avg_ns": t5_avg,
            "t_rotate_ns": t_rotate_frame,
            "packet_phase_ns": packet_phase,
            "t_sleep_ns": t_sleep,
            "applied_delay_ns": applied,
            "rolling_error_mean_ns": roll_mean,
            "rolling_error_var_ns2": roll_var,
        }
    )
    if not n:
        warnings.append("no frames: nothing to pair with the LiDAR")
    if not np.isfinite(duration).any() and n:
        warnings.append("no exposure metadata: t5 and t_l unknown (set assumed_exposure_us)")
    for name in LATENCIES:
        if stats[name].status == "not observed":
            warnings.append(f"{name} not observed in the log (set analysis.assumed_{name}_us)")
    return CameraSync(
        camera=camera.name,
        theta_deg=theta,
        omega_deg_s=omega_mean,
        t_rotate_ns=t_rotate,
        packet_phase_ns=phase_mean,
        latencies=stats,
        t5_mean_ns=t5_mean,
        delay_applied_ns=applied_mean,
        delay_recommended_ns=recommended,
        delay_from_error_ns=applied_mean - float(s.mean()) if s.size else math.nan,
        frames_total=n,
        frames_paired=int(paired.sum()),
        unpaired={k: v for k, v in unpaired.items() if v},
        error_signed_mean_ns=float(s.mean()) if s.size else math.nan,
        error_mean_ns=mean_e,
        error_var_ns2=var_e,
        error_p99_ns=float(np.percentile(e, 99)) if e.size else math.nan,
        error_max_ns=float(e.max()) if e.size else math.nan,
        rolling_mean_max_ns=float(np.nanmax(roll_mean))
        if np.isfinite(roll_mean).any()
        else math.nan,
        rolling_var_max_ns2=float(np.nanmax(roll_var)) if np.isfinite(roll_var).any() else math.nan,
        mean_exceeded=bool(mean_e > thr_mean),
        var_exceeded=bool(var_e > thr_var),
        frames=table,
        warnings=warnings,
    )
