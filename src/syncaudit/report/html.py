"""A self-contained HTML report: no scripts, no external assets, plots as inline SVG."""

from __future__ import annotations

import html
import math
from collections.abc import Sequence

import numpy as np

from syncaudit.audit import AuditResult, CameraAudit

_STYLE = """
body{font:14px/1.45 system-ui,sans-serif;margin:2rem auto;max-width:1100px;color:#222}
h1{font-size:1.4rem}h2{font-size:1.15rem;margin-top:2rem}table{border-collapse:collapse;margin:.5rem 0}
td,th{border:1px solid #ccc;padding:.25rem .6rem;text-align:left}th{background:#f3f3f3}
.pass{color:#176f2c;font-weight:600}.fail{color:#b00020;font-weight:600}.warn{color:#8a5a00}
svg{border:1px solid #ddd;background:#fff}.num{text-align:right;font-variant-numeric:tabular-nums}
"""


def _e(value: object) -> str:
    return html.escape(str(value))


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


def error_plot_svg(
    series: Sequence[tuple[str, str, np.ndarray]],
    limit_us: float,
    width: int = 1000,
    height: int = 220,
) -> str:
    """Signed error (us) per frame for each series, with the +-limit band, as inline SVG."""
    finite = [s[2][np.isfinite(s[2])] for s in series]
    values = np.concatenate(finite) if finite else np.empty(0)
    if values.size == 0:
        return "<p>No paired frames to plot.</p>"
    span = max(float(np.max(np.abs(values))), limit_us) * 1.1
    n = max(len(s[2]) for s in series)
    pad = 40

    def x(i: int) -> float:
        return pad + (width - 2 * pad) * (i / max(n - 1, 1))

    def y(v: float) -> float:
        return height / 2 - (height / 2 - 10) * (v / span)

    parts = [
        f'<svg width="{width}" height="{height}" role="img" aria-label="sync error per frame">',
        f'<rect x="{pad}" y="{y(limit_us):.1f}" width="{width - 2 * pad}" '
        f'height="{y(-limit_us) - y(limit_us):.1f}" fill="#e8f5e9"/>',
        f'<line x1="{pad}" x2="{width - pad}" y1="{y(0):.1f}" y2="{y(0):.1f}" stroke="#999"/>',
        f'<text x="4" y="{y(span / 1.1) + 4:.1f}" font-size="11">{span / 1.1:,.0f} us</text>',
        f'<text x="4" y="{y(-span / 1.1):.1f}" font-size="11">{-span / 1.1:,.0f} us</text>',
    ]
    for label, colour, data in series:
        points = " ".join(
            f"{x(i):.1f},{y(float(v)):.1f}" for i, v in enumerate(data) if math.isfinite(float(v))
        )
        parts.append(
            f'<polyline fill="none" stroke="{colour}" stroke-width="1.2" points="{points}">'
            f"<title>{_e(label)}</title></polyline>"
        )
    legend_y = 14
    for label, colour, _ in series:
        parts.append(
            f'<text x="{width - 260}" y="{legend_y}" font-size="11" fill="{colour}">{_e(label)}</text>'
        )
        legend_y += 14
    parts.append("</svg>")
    return "".join(parts)


def _camera_section(cam: CameraAudit, limit_us: float) -> str:
    d = cam.to_dict()
    verdict = (
        f'<span class="fail">not judged</span> ({_e(str(cam.sync.not_judged_reason))})'
        if not cam.sync.judged
        else '<span class="fail">needs correction</span>'
        if cam.sync.needs_correction
        else '<span class="pass">within thresholds</span>'
    )
    rows = [
        ("theta (deg) / omega (deg/s)", f"{_fmt(d['theta_deg'], 2)} / {_fmt(d['omega_deg_s'])}"),
        ("t_rotate, Eq. 1 (us)", _fmt(d["t_rotate_us"])),
    ]
    for name, lat in d["latencies"].items():
        rows.append(
            (
                f"{name} mean / p50 / p99 (us)",
                f"{_fmt(lat['mean_us'])} / {_fmt(lat['p50_us'])} / {_fmt(lat['p99_us'])} "
                f"({_e(lat['status'])})",
            )
        )
    rows += [
        ("t5 mean exposure, Eq. 3 (us)", _fmt(d["t5_mean_us"])),
        ("t_sleep applied (us)", _fmt(d["delay_applied_us"])),
        ("t_sleep recommended, Eq. 2 (us)", f"<b>{_fmt(d['delay_recommended_us'])}</b>"),
        ("error mean, Eq. 5 (us)", _fmt(d["error_mean_us"])),
        ("error variance, Eq. 6 (us^2)", _fmt(d["error_var_us2"])),
        (
            "error signed mean / p99 / max (us)",
            f"{_fmt(d['error_signed_mean_us'])} / {_fmt(d['error_p99_us'])} / {_fmt(d['error_max_us'])}",
        ),
        ("frames paired / total", f"{d['frames_paired']} / {d['frames_total']}"),
    ]
    rows += [(f"unpaired: {k}", str(v)) for k, v in d["unpaired"].items()]
    series = [("recorded error", "#1f5fbf", cam.sync.frames["error_signed_ns"].to_numpy() / 1e3)]
    if cam.replay is not None:
        c = d["corrected"]
        rows.append(
            (
                "with self-adaptive correction (replayed)",
                f"{c['adjustments']} adjustments; after the first: mean "
                f"{_fmt(c['settled_error_mean_us'])} us, var {_fmt(c['settled_error_var_us2'])} us^2",
            )
        )
        series.append(("with correction (replayed)", "#e07b00", cam.replay.errors_ns / 1e3))
    warnings = "".join(f'<p class="warn">warning: {_e(w)}</p>' for w in cam.sync.warnings)
    return (
        f"<h2>camera {_e(cam.sync.camera)}: {verdict}</h2>{_table(rows)}"
        f"<p>Signed error t_l - t_estimated per frame (green band: the Eq. 5 limit).</p>"
        f"{error_plot_svg(series, limit_us)}{warnings}"
    )


def render_audit_html(result: AuditResult, extra_sections: Sequence[str] = ()) -> str:
    """The whole audit as one HTML page; `extra_sections` are appended (e.g. calibration)."""
    lidar = result.lidar
    verdict = result.verdict.upper()
    css = "pass" if result.passed else "fail"
    head = _table(
        [
            ("log", _e(result.path)),
            ("container / duration", f"{_e(result.container)} / {_fmt(result.duration_s, 3)} s"),
            ("LiDAR", f"{_e(lidar.topic)}: {_e(lidar.vendor)} {_e(lidar.model)}"),
            ("RPM / revolutions", f"{_fmt(lidar.rpm, 2)} / {lidar.revolutions}"),
            (
                "packets per revolution / dropped",
                f"{_fmt(lidar.packets_per_revolution, 0)} / {lidar.dropped_packets}",
            ),
            (
                "clock",
                "synchronised"
                if lidar.clock_synchronised
                else f"NOT synchronised (host - sensor {_signed(lidar.clock_offset_s, 3)} s)",
            ),
            ("t1 p50 / p99 (us)", f"{_fmt(lidar.t1_p50_us)} / {_fmt(lidar.t1_p99_us)}"),
        ]
    )
    limit_us = result.rig.thresholds.error_mean_us
    cams = "".join(_camera_section(c, limit_us) for c in result.cameras)
    notes = "".join(
        f'<p class="warn">{_e(kind)}: {_e(text)}</p>'
        for kind, items in (
            ("missing", result.missing),
            ("guessed", result.guessed),
            ("warning", result.warnings),
        )
        for text in items
    )
    return (
        "<!doctype html><html lang=en><head><meta charset=utf-8>"
        f"<title>syncaudit: {_e(result.path)}</title><style>{_STYLE}</style></head><body>"
        f'<h1>syncaudit audit: <span class="{css}">{verdict}</span></h1>{head}{notes}{cams}'
        + "".join(extra_sections)
        + "</body></html>\n"
    )
