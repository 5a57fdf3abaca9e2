"""The trigger design in the HTML report: a rolling-shutter camera's error against image row
(one small inline SVG), the design's table rows, the LiDAR's phase-lock line.

Each row exposes a row time after the one above it, so the error against the LiDAR grows
down the image; the plot shows the mean signed error at the profile rows the audit gives
(`trigger_design.rolling_shutter.profile`), the target row and zero.
"""

from __future__ import annotations

from typing import Any

from syncaudit.report.plot import COLOURS, esc, nice_ticks, tick_labels

WIDTH, HEIGHT = 480, 230
LEFT, RIGHT, TOP, BOTTOM = 64, 16, 28, 40


def row_error_svg(rows: dict[str, Any] | None) -> str:
    """`<figure class="rows">` of signed error (us) against row; "" for a global shutter."""
    if not rows:
        return ""
    points = [
        (float(p["row"]), float(p["error_signed_mean_us"]))
        for p in rows["profile"]
        if p["error_signed_mean_us"] is not None
    ]
    if len(points) < 2:
        return ""
    x_hi = float(rows["rows"] - 1) or 1.0
    errors = [e for _, e in points] + [0.0]
    ticks = nice_ticks(min(errors), max(errors), 5)
    y_lo, y_hi = min(ticks[0], min(errors)), max(ticks[-1], max(errors))
    span = (y_hi - y_lo) or 1.0

    def x(row: float) -> float:
        return LEFT + row / x_hi * (WIDTH - LEFT - RIGHT)

    def y(err: float) -> float:
        return TOP + (y_hi - err) / span * (HEIGHT - TOP - BOTTOM)

    line = " ".join(f"{x(r):.1f},{y(e):.1f}" for r, e in points)
    target = int(rows["target_row"])
    parts = [
        f'<svg width="{WIDTH}" height="{HEIGHT}" viewBox="0 0 {WIDTH} {HEIGHT}" '
        'role="img" aria-label="error against image row">',
        f'<text x="{LEFT}" y="16" font-size="13">signed error against image row '
        f"({rows['rows']} rows, {rows['row_time_us']:g} µs a row)</text>",
        f'<line x1="{LEFT}" x2="{WIDTH - RIGHT}" y1="{y(0.0):.1f}" y2="{y(0.0):.1f}" '
        'stroke="#999" stroke-dasharray="3 3"/>',
        f'<line x1="{x(target):.1f}" x2="{x(target):.1f}" y1="{TOP}" y2="{HEIGHT - BOTTOM}" '
        'stroke="#c33" stroke-dasharray="4 2"/>',
        f'<text x="{x(target) + 4:.1f}" y="{TOP + 12}" font-size="11" fill="#c33">'
        f"target row {target}</text>",
        f'<polyline fill="none" stroke="{COLOURS[0]}" stroke-width="2" points="{line}"/>',
    ]
    for tick, label in zip(ticks, tick_labels(ticks), strict=True):
        parts.append(
            f'<text x="{LEFT - 6}" y="{y(tick) + 4:.1f}" font-size="11" '
            f'text-anchor="end">{esc(label)}</text>'
        )
    for row in (0, target, rows["rows"] - 1):
        parts.append(
            f'<text x="{x(row):.1f}" y="{HEIGHT - BOTTOM + 16}" font-size="11" '
            f'text-anchor="middle">{row}</text>'
        )
    parts.append(
        f'<text x="{(LEFT + WIDTH) / 2:.0f}" y="{HEIGHT - 6}" font-size="11" '
        'text-anchor="middle">image row (top 0) · error µs</text></svg>'
    )
    return f'<figure class="rows" data-kind="row-error">{"".join(parts)}</figure>'


def design_rows(design: dict[str, Any] | None) -> list[tuple[str, str]]:
    """Rows of the camera table: the design, why, and what to set (HTML-escaped)."""
    if not design:
        return []
    rec = design["recommendation"]
    rows = [
        ("trigger design", f"<b>{esc(design['design'])}</b> ({esc(design['why'])})"),
        (
            "recommendation (replayed)",
            f"{esc(rec['action'])}, shift {esc(rec['shift_us'])} µs: Eq. 5 "
            f"{esc(rec['current_error_mean_us'])} -> {esc(rec['expected_error_mean_us'])} µs "
            f"(floor {esc(rec['floor_us'])} µs)",
        ),
    ]
    if rec.get("set"):
        s = rec["set"]
        rows.append(("set", f"<b>{esc(s['parameter'])} = {esc(s['value'])} {esc(s['unit'])}</b>"))
    return rows


def phase_lock_html(lock: dict[str, Any] | None) -> str:
    """One paragraph on the LiDAR's phase lock ("" where there is nothing to say)."""
    if not lock:
        return ""
    if not lock.get("judged"):
        return f'<p class="phase-lock">phase lock not judged: {esc(lock.get("why"))}</p>'
    state = "locked" if lock["locked"] else "not locked"
    lost = "; ".join(
        f"lost {span['start_s']}-{span['end_s']} s (up to {span['max_offset_us']} µs)"
        for span in lock.get("lost_lock", [])
    )
    return (
        f'<p class="phase-lock">phase lock: {state} at {esc(lock["lock_azimuth_deg"])} deg '
        f"({esc(lock['lock_azimuth_source'])}), offset {esc(lock['offset_mean_us'])} µs, "
        f"jitter {esc(lock['jitter_us'])} µs, drift {esc(lock['drift_us_per_s'])} µs/s"
        + (f"; {esc(lost)}" if lost else "")
        + "</p>"
    )
