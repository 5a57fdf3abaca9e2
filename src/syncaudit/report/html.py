"""The per-log HTML report: one self-contained, offline file (inline SVG, style and script).

The header says the verdict, what was judged and what was not (and why) and every
warning; each camera gets its signed error over log time (recorded and with the replayed
self-adaptive correction, the Eq. 5 band), rolling Eq. 5 / Eq. 6 against their limits, a
histogram of |error|, t1..t4 per frame, exposure against the Eq. 3 running average and
the delay applied against Eq. 2's; the LiDAR gets RPM, packets, drops (gaps in the packet
cadence) and the sensor-vs-host clock (with its rolling minimum, the offset) per
revolution. See docs/report.md for why plots are hand SVG.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from syncaudit.audit.run import AuditResult, CameraAudit
from syncaudit.report.advice_text import advice_sentence
from syncaudit.report.plot import (
    COLOURS,
    Band,
    Series,
    TimePlot,
    esc,
    histogram_svg,
    time_plot_svg,
)
from syncaudit.report.row_error import design_rows, phase_lock_html, row_error_svg
from syncaudit.report.script import SCRIPT, STYLE
from syncaudit.writers.provenance import HTML_MARK

_e = esc


def _fmt(value: float | None, digits: int = 1) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    return f"{value:,.{digits}f}"


def _signed(value: float | None, digits: int) -> str:
    """A number with its sign always shown (clock offsets: which clock is ahead matters)."""
    if value is None or not math.isfinite(value):
        return "-"
    return f"{value:+,.{digits}f}"


def _table(rows: Sequence[tuple[str, str]]) -> str:
    body = "".join(f"<tr><th>{_e(k)}</th><td class=num>{v}</td></tr>" for k, v in rows)
    return f"<table>{body}</table>"


def _floats(values: object) -> NDArray[np.float64]:
    """A pandas column (nullable ints included) as float64 with NaN for missing."""
    import pandas as pd

    out = pd.Series(values).astype("Float64").to_numpy(np.float64, na_value=np.nan)
    return np.asarray(out, dtype=np.float64)


def frame_time_ns(cam: CameraAudit) -> NDArray[np.float64]:
    """Each frame's time on the host clock: mid-exposure, else exposure start, else header."""
    f = cam.sync.frames
    t = _floats(f["t_l_ns"])
    for col in ("exposure_start_ns", "header_stamp_ns"):
        t = np.where(np.isfinite(t), t, _floats(f[col]))
    return t


def time_origin_ns(result: AuditResult) -> float:
    """The report's t = 0: the log start, else the first frame or revolution."""
    if result.start_ns is not None:
        return float(result.start_ns)
    firsts = [
        float(np.nanmin(t)) for c in result.cameras if np.isfinite(t := frame_time_ns(c)).any()
    ]
    revs = result.revolutions
    if revs is not None and revs.count:
        firsts.append(float(revs.zero_packet_driver_ns.min()))
    return min(firsts, default=0.0)


def _x_range(result: AuditResult, origin: float) -> tuple[float, float]:
    end = result.duration_s
    if end is None or not end > 0:
        lasts = [
            float(np.nanmax(t)) for c in result.cameras if np.isfinite(t := frame_time_ns(c)).any()
        ]
        end = (max(lasts, default=origin + 1e9) - origin) / 1e9
    return 0.0, max(float(end), 1e-3)


def camera_plots(cam: CameraAudit, result: AuditResult, origin_ns: float) -> list[TimePlot]:
    """The time plots of one camera (in page order, before the t1..t4 small multiples)."""
    f = cam.sync.frames
    t_s = (frame_time_ns(cam) - origin_ns) / 1e9
    th = result.rig.thresholds
    window = result.rig.analysis.window_frames
    recorded = _floats(f["error_signed_ns"]) / 1e3
    paired = f["paired"].to_numpy(dtype=bool)
    recorded = np.where(paired, recorded, np.nan)
    error = TimePlot(
        "Signed error t_l - t_estimated per frame (Eq. 4)",
        "µs",
        kind="error",
        bands=[Band(-th.error_mean_us, th.error_mean_us, f"Eq. 5 limit ±{th.error_mean_us:g} µs")],
    )
    error.series.append(Series("recorded", t_s, recorded, COLOURS[0]))
    mean = TimePlot(
        f"Rolling Eq. 5 mean of |error| over {window} frames",
        "µs",
        kind="rolling-mean",
        limits=[(th.error_mean_us, f"limit {th.error_mean_us:g} µs")],
    )
    mean.series.append(
        Series("recorded", t_s, _floats(f["rolling_error_mean_ns"]) / 1e3, COLOURS[0])
    )
    var = TimePlot(
        f"Rolling Eq. 6 variance of |error| over {window} frames",
        "µs²",
        kind="rolling-var",
        limits=[(th.error_var_us2, f"limit {th.error_var_us2:,.0f} µs²")],
    )
    var.series.append(
        Series("recorded", t_s, _floats(f["rolling_error_var_ns2"]) / 1e6, COLOURS[0])
    )
    delay = TimePlot(
        "Trigger delay t_sleep: applied, Eq. 2 recommended, controller replay",
        "µs",
        kind="delay",
    )
    delay.series += [
        Series("applied", t_s, _floats(f["applied_delay_ns"]) / 1e3, COLOURS[0], step=True),
        Series("Eq. 2 recommended", t_s, _floats(f["t_sleep_ns"]) / 1e3, COLOURS[2], step=True),
    ]
    if cam.replay is not None:
        from syncaudit.analysis.stats import rolling_mean, rolling_variance

        corrected_ns, delays_ns = cam.replay.per_frame(len(f))
        error.series.append(
            Series("with self-adaptive correction (replayed)", t_s, corrected_ns / 1e3, COLOURS[1])
        )
        ok = np.isfinite(corrected_ns)
        abs_corr = np.abs(corrected_ns[ok])
        roll_mean = np.full(len(f), np.nan)
        roll_var = np.full(len(f), np.nan)
        roll_mean[ok] = rolling_mean(abs_corr, window)
        roll_var[ok] = rolling_variance(abs_corr, window)
        mean.series.append(Series("replayed correction", t_s, roll_mean / 1e3, COLOURS[1]))
        var.series.append(Series("replayed correction", t_s, roll_var / 1e6, COLOURS[1]))
        delay.series.append(
            Series("controller replay", t_s, delays_ns / 1e3, COLOURS[1], step=True)
        )
        adj_t = t_s[cam.replay.adjustment_rows]
        delay.series.append(
            Series(
                "replay adjustments",
                adj_t,
                cam.replay.adjustment_delays_ns.astype(np.float64) / 1e3,
                COLOURS[4],
                dots=True,
            )
        )
    exposure = TimePlot(
        "Exposure t5 per frame and its Eq. 3 running average", "µs", kind="exposure"
    )
    exposure.series += [
        Series("exposure t5_i", t_s, _floats(f["exposure_duration_ns"]) / 1e3, COLOURS[0]),
        Series("running average t5 (Eq. 3)", t_s, _floats(f["t5_avg_ns"]) / 1e3, COLOURS[1]),
    ]
    return [error, mean, var, exposure, delay]


def latency_plots(cam: CameraAudit, origin_ns: float) -> list[TimePlot]:
    """t1..t4 per frame, one small plot each (the trigger chain)."""
    f = cam.sync.frames
    t_s = (frame_time_ns(cam) - origin_ns) / 1e9
    names = {
        "t1": "t1 LiDAR packet -> host (driver)",
        "t2": "t2 host -> camera driver",
        "t3": "t3 camera driver -> sensor (less applied delay)",
        "t4": "t4 sensor trigger -> exposure start",
    }
    plots = []
    for i, (key, title) in enumerate(names.items()):
        status = cam.sync.latencies[key].status if key in cam.sync.latencies else "not observed"
        plot = TimePlot(f"{title} ({status})", "µs", kind=f"latency-{key}", width=500, height=170)
        plot.series.append(Series(key, t_s, _floats(f[f"{key}_ns"]) / 1e3, COLOURS[i % 4]))
        plots.append(plot)
    return plots


CLOCK_WINDOW_S = 10.0
"""Span of the rolling minimum of host - sensor: the fastest packet in it had about no
queueing, so the minimum follows the clock offset and its drift (minutes) without the t1
jitter (one revolution's zero packet per point: 100 points at 10 Hz)."""


def rolling_min(values: NDArray[np.float64], window: int) -> NDArray[np.float64]:
    """Minimum over each value and the `window - 1` before it (fewer at the start)."""
    if values.size == 0 or window <= 1:
        return values.copy()
    padded = np.concatenate([np.full(window - 1, np.inf), values])
    out: NDArray[np.float64] = np.lib.stride_tricks.sliding_window_view(padded, window).min(axis=1)
    return out


def lidar_plots(result: AuditResult, origin_ns: float) -> list[TimePlot]:
    """RPM, packets, drops and the sensor-vs-host clock, one point per revolution."""
    revs = result.revolutions
    if revs is None or revs.count == 0:
        return []
    host = revs.zero_packet_driver_ns.astype(np.float64)
    t_s = (host - origin_ns) / 1e9
    rpm = TimePlot("Rotation rate per revolution", "RPM", kind="lidar-rpm")
    rpm.series.append(Series("RPM", t_s, revs.omega_deg_s / 6.0, COLOURS[0]))
    packets = TimePlot(
        "Packets per revolution (the first and last are partial)",
        "packets",
        kind="lidar-packets",
        counts=True,
    )
    packets.series.append(Series("packets", t_s, revs.packets.astype(np.float64), COLOURS[0]))
    dropped = revs.dropped_packets
    hit = dropped > 0
    counted = (
        f"{int(dropped.sum()):,} in {int(hit.sum()):,} of {revs.count:,} revolutions"
        if hit.any()
        else f"none in {revs.count:,} revolutions"
    )
    drops = TimePlot(
        "Packets dropped: gaps in the packet cadence, per revolution "
        f"({counted}; a FOV crop is not counted)",
        "packets",
        kind="lidar-drops",
        height=170,
        counts=True,
    )
    drops.series.append(
        Series("dropped", t_s[hit], dropped[hit].astype(np.float64), COLOURS[4], dots=True)
    )
    raw = (revs.zero_packet_driver_ns - revs.zero_packet_sensor_ns).astype(np.float64)
    median = float(np.median(raw))
    big = abs(median) > 1e9
    ref = median if big else 0.0
    title = "Host (driver stamp) minus sensor clock, per revolution"
    if big:
        title += f", less the median {median / 1e9:+,.3f} s"
    clock = TimePlot(title, "µs", kind="lidar-clock")
    period_s = float(np.median(np.diff(t_s))) if t_s.size > 1 else math.nan
    window = max(1, round(CLOCK_WINDOW_S / period_s)) if period_s > 0 else 1
    window = min(window, revs.count)  # a short log: over all of it
    clock.series += [
        Series("host - sensor", t_s, (raw - ref) / 1e3, COLOURS[0]),
        Series(
            f"minimum over {window} revolutions ({window * period_s:.3g} s): the offset, "
            "t1 jitter removed",
            t_s,
            rolling_min(raw - ref, window) / 1e3,
            COLOURS[1],
        ),
    ]
    return [rpm, packets, drops, clock]


def _camera_table(cam: CameraAudit) -> str:
    d = cam.to_dict()
    rows = [
        ("azimuth (deg) / source", f"{_fmt(d['azimuth_deg'], 2)} / {_e(d['azimuth_source'])}"),
        ("theta (deg) / omega (deg/s)", f"{_fmt(d['theta_deg'], 2)} / {_fmt(d['omega_deg_s'])}"),
        ("t_rotate, Eq. 1 (µs)", _fmt(d["t_rotate_us"])),
        (
            "packet phase (µs) / source",
            f"{_fmt(d['packet_phase_us'])} / {_e(d['packet_phase_source'])}",
        ),
        ("frames paired with triggers by", _e(d["trigger_pairing"])),
    ]
    for name, lat in d["latencies"].items():
        rows.append(
            (
                f"{name} mean / p50 / p99 (µs)",
                f"{_fmt(lat['mean_us'])} / {_fmt(lat['p50_us'])} / {_fmt(lat['p99_us'])} "
                f"({_e(lat['status'])})",
            )
        )
    rows += [
        ("t5 mean exposure, Eq. 3 (µs)", _fmt(d["t5_mean_us"])),
        ("t_sleep applied (µs)", _fmt(d["delay_applied_us"])),
        ("t_sleep recommended, Eq. 2 (µs)", f"<b>{_fmt(d['delay_recommended_us'])}</b>"),
        ("error mean, Eq. 5 (µs)", _fmt(d["error_mean_us"])),
        ("error variance, Eq. 6 (µs²)", _fmt(d["error_var_us2"])),
        (
            "error signed mean / p99 / max (µs)",
            f"{_fmt(d['error_signed_mean_us'])} / {_fmt(d['error_p99_us'])} / {_fmt(d['error_max_us'])}",
        ),
        ("frames paired / total", f"{d['frames_paired']} / {d['frames_total']}"),
    ]
    rows += [(f"unpaired: {k}", str(v)) for k, v in d["unpaired"].items()]
    c = d["corrected"]
    if c is not None:
        rows.append(
            (
                "with self-adaptive correction (replayed)",
                f"{c['adjustments']} adjustments; after the first: Eq. 5 "
                f"{_fmt(c['settled_error_mean_us'])} µs, Eq. 6 {_fmt(c['settled_error_var_us2'])} µs²",
            )
        )
    rows += design_rows(d.get("trigger_design"))
    return _table(rows)


_VERDICT_CSS = {"pass": "pass", "fail": "fail", "not judged": "notjudged"}


def _camera_section(
    cam: CameraAudit, result: AuditResult, origin: float, xr: tuple[float, float]
) -> str:
    verdict = cam.sync.verdict
    label = {"pass": "within thresholds", "fail": "needs correction"}.get(verdict, verdict)
    reason = f" ({_e(cam.sync.not_judged_reason)})" if cam.sync.not_judged_reason else ""
    optional = " (optional)" if cam.sync.optional else ""
    th = result.rig.thresholds
    plots = camera_plots(cam, result, origin)
    err = np.abs(_floats(cam.sync.frames["t_error_ns"])) / 1e3
    warnings = "".join(f'<li class="warn">{_e(w)}</li>' for w in cam.sync.warnings)
    advice = advice_sentence(cam.sync.camera, cam.to_dict().get("recommendation"))
    return (
        f'<section class="camera" data-camera="{_e(cam.sync.camera)}">'
        f"<h2>camera {_e(cam.sync.camera)}{optional}: "
        f'<span class="{_VERDICT_CSS.get(verdict, "warn")}">{_e(label)}</span>{reason}</h2>'
        + (f'<p class="advice"><b>Advice</b> — {_e(advice)}</p>' if advice else "")
        + (f'<ul class="notes">{warnings}</ul>' if warnings else "")
        + '<div class="row">'
        + _camera_table(cam)
        + histogram_svg(
            err,
            title="|error| per paired frame",
            unit="µs",
            limit=th.error_mean_us,
            limit_label=f"Eq. 5 limit {th.error_mean_us:g} µs",
        )
        + row_error_svg((cam.design or {}).get("rolling_shutter"))
        + "</div>"
        + "".join(time_plot_svg(p, x_range=xr) for p in plots[:3])
        + "<h3>Trigger chain t1..t4 per frame</h3><div class='row'>"
        + "".join(time_plot_svg(p, x_range=xr) for p in latency_plots(cam, origin))
        + "</div>"
        + "".join(time_plot_svg(p, x_range=xr) for p in plots[3:])
        + "</section>"
    )


def _header(result: AuditResult) -> str:
    lidar = result.lidar
    clock = (
        "unknown"
        if lidar.clock_synchronised is None
        else f"synchronised (host - sensor {_signed(lidar.clock_offset_s, 6)} s)"
        if lidar.clock_synchronised
        else f"NOT synchronised (host - sensor {_signed(lidar.clock_offset_s, 6)} s)"
    )
    facts = _table(
        [
            ("log", _e(result.path)),
            ("container / duration", f"{_e(result.container)} / {_fmt(result.duration_s, 3)} s"),
            ("LiDAR", f"{_e(lidar.topic)}: {_e(lidar.vendor)} {_e(lidar.model)}"),
            ("RPM / revolutions", f"{_fmt(lidar.rpm, 2)} / {lidar.revolutions}"),
            (
                "packets per revolution / dropped",
                f"{_fmt(lidar.packets_per_revolution, 0)} / {lidar.dropped_packets}",
            ),
            ("clock", _e(clock)),
            ("t1 p50 / p99 (µs)", f"{_fmt(lidar.t1_p50_us)} / {_fmt(lidar.t1_p99_us)}"),
            (
                "thresholds",
                f"Eq. 5 mean {result.rig.thresholds.error_mean_us:g} µs, Eq. 6 variance "
                f"{result.rig.thresholds.error_var_us2:,.0f} µs², window "
                f"{result.rig.analysis.window_frames} frames",
            ),
        ]
    )
    judged = [
        f'<li><span class="{_VERDICT_CSS.get(c.sync.verdict, "warn")}">{_e(c.sync.verdict)}</span>: '
        f"camera {_e(c.sync.camera)}"
        + (" (optional)" if c.sync.optional else "")
        + (f" — {_e(c.sync.not_judged_reason)}" if c.sync.not_judged_reason else "")
        + "</li>"
        for c in result.cameras
    ]
    lists = [
        ("Cameras: verdict each", judged),
        ("Not judged (fails the audit)", [f"<li>{_e(x)}</li>" for x in result.not_judged]),
        ("Missing from the log", [f"<li>{_e(x)}</li>" for x in result.missing]),
        ("Guessed", [f"<li>{_e(x)}</li>" for x in result.guessed]),
        (
            "Warnings",
            [f'<li class="warn">{_e(x)}</li>' for x in result.warnings],
        ),
    ]
    body = "".join(
        f'<h3>{_e(title)}</h3><ul class="notes" data-list="{_e(title)}">{"".join(items)}</ul>'
        for title, items in lists
        if items
    )
    return facts + body


def audit_sections(result: AuditResult, *, under_gate: bool = False) -> str:
    """The audit's part of a report page: header, LiDAR plots, one section per camera.

    `under_gate`: the page leads with a gate's policy verdict, so the audit's own verdict
    (against the rig's thresholds) is a second-level heading saying so, not the title."""
    origin = time_origin_ns(result)
    xr = _x_range(result, origin)
    css = _VERDICT_CSS.get(result.verdict, "warn")
    lidar = "".join(time_plot_svg(p, x_range=xr) for p in lidar_plots(result, origin))
    verdict = f'<span class="{css}" id="verdict">{_e(result.verdict.upper())}</span>'
    heading = (
        f"<h2>The audit's own verdict (the rig's thresholds, not the policy's): {verdict}</h2>"
        if under_gate
        else f"<h1>syncaudit audit: {verdict}</h1>"
    )
    return (
        heading
        + _header(result)
        + '<p class="hint">Time plots: hover for values and wall-clock time, drag to zoom '
        "every time axis, double-click to reset.</p>"
        + (
            f'<section class="lidar"><h2>LiDAR {_e(result.lidar.topic)}</h2>'
            f"{phase_lock_html(result.phase_lock)}{lidar}</section>"
            if lidar
            else ""
        )
        + "".join(_camera_section(c, result, origin, xr) for c in result.cameras)
    )


def page(title: str, body: str, *, t0_ns: float | None = None) -> str:
    """A whole self-contained page around `body` (style and script inline)."""
    t0 = f' data-t0-ms="{t0_ns / 1e6:.3f}"' if t0_ns is not None and t0_ns > 0 else ""
    return (
        "<!doctype html><html lang=en><head><meta charset=utf-8>"
        + HTML_MARK
        + f"<title>{_e(title)}</title><style>{STYLE}</style></head><body{t0}>"
        f"{body}<script>{SCRIPT}</script></body></html>\n"
    )


def render_audit_html(result: AuditResult, extra_sections: Sequence[str] = ()) -> str:
    """The whole audit as one HTML page; `extra_sections` (HTML) are appended."""
    return page(
        f"syncaudit: {result.path}",
        audit_sections(result) + "".join(extra_sections),
        t0_ns=time_origin_ns(result),
    )
