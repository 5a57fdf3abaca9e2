"""Inline SVG plots for the HTML reports: time plots with real axes, histograms, x-y maps.

Everything is drawn here in Python as SVG (readable without script); the page's small
inline script (`syncaudit.report.script`) adds hover read-outs and zoom on time. A time
plot's data sit in a nested <svg class="area"> whose viewBox is in data units (seconds,
and the series' unit with y negated), so zooming is a viewBox change. Series longer than
`MAX_POINTS` are decimated to min/max envelopes, which keep every spike visible.
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

MAX_POINTS = 2000
"""Points per series beyond which a series is drawn as a min/max envelope."""

WIDTH = 1000
HEIGHT = 230
LEFT, RIGHT, TOP, BOTTOM = 70, 12, 22, 34
COLOURS = ("#1f5fbf", "#e07b00", "#2a9d3f", "#9c3fbf", "#b0283a", "#5f6f7f")


def esc(value: object) -> str:
    """Escape text for HTML text and attribute values."""
    return html.escape(str(value), quote=True)


@dataclass(frozen=True, slots=True)
class Series:
    """One line of a time plot: x in seconds, y in the plot's unit (NaN: no value)."""

    label: str
    x_s: NDArray[np.float64]
    y: NDArray[np.float64]
    colour: str = COLOURS[0]
    step: bool = False
    """Held values (e.g. a delay): runs of equal values keep their ends, no gap breaks."""
    dots: bool = False
    """Drawn as dots (events, e.g. the controller's adjustments), never decimated."""


@dataclass(frozen=True, slots=True)
class Band:
    """A horizontal band (a limit drawn as an area), in the plot's unit."""

    low: float
    high: float
    label: str
    colour: str = "#dcefdc"


@dataclass(slots=True)
class TimePlot:
    """A plot over log time: series, limit bands and lines, labelled axes."""

    title: str
    unit: str
    series: list[Series] = field(default_factory=list)
    bands: list[Band] = field(default_factory=list)
    limits: list[tuple[float, str]] = field(default_factory=list)
    """Horizontal limit lines: (value, label)."""
    height: int = HEIGHT
    width: int = WIDTH
    kind: str = ""
    """Name of the plot for tests and styling (data-kind)."""
    counts: bool = False
    """A count (packets): the axis starts at zero and ticks are whole numbers."""


def envelope(
    x: NDArray[np.float64], y: NDArray[np.float64], max_points: int = MAX_POINTS
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The finite points, or beyond `max_points` each bucket's min and max in time order."""
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if x.size <= max_points:
        return x, y
    buckets = max_points // 2
    edges = np.linspace(0, x.size, buckets + 1).astype(np.int64)[:-1]
    starts = np.unique(edges)
    lo = np.minimum.reduceat(y, starts)
    hi = np.maximum.reduceat(y, starts)
    idx = np.arange(x.size)
    # The index of each bucket's min and max: first position equal to the reduced value.
    bucket = np.searchsorted(starts, idx, side="right") - 1
    at_lo = np.where(y == lo[bucket], idx, x.size)
    at_hi = np.where(y == hi[bucket], idx, x.size)
    i_lo = np.minimum.reduceat(at_lo, starts)
    i_hi = np.minimum.reduceat(at_hi, starts)
    keep = np.unique(np.concatenate([i_lo, i_hi]))
    return x[keep], y[keep]


def steps_only(
    x: NDArray[np.float64], y: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Drop the inner points of runs of equal values (lossless for a held value)."""
    if y.size < 3:
        return x, y
    same_prev = np.r_[False, y[1:] == y[:-1]]
    same_next = np.r_[y[:-1] == y[1:], False]
    keep = ~(same_prev & same_next)
    return x[keep], y[keep]


def nice_ticks(low: float, high: float, count: int = 6) -> list[float]:
    """Round tick values (1, 2, 5 x 10^k) covering [low, high]."""
    if not (math.isfinite(low) and math.isfinite(high)) or high <= low:
        return [low] if math.isfinite(low) else []
    raw = (high - low) / count
    power = 10 ** math.floor(math.log10(raw))
    step = next(m * power for m in (1, 2, 5, 10) if m * power >= raw)
    first = math.ceil(low / step) * step
    ticks = []
    value = first
    while value <= high + step * 1e-9:
        ticks.append(0.0 if abs(value) < step * 1e-9 else value)
        value += step
    return ticks


def tick_labels(ticks: Sequence[float]) -> list[str]:
    """Labels with the decimals the tick spacing needs (599.9, 600.0, 600.1), thousands
    separated."""
    step = abs(ticks[1] - ticks[0]) if len(ticks) > 1 else abs(ticks[0]) if ticks else 1.0
    decimals = max(0, -math.floor(math.log10(step) + 1e-9)) if 0 < step < 1 else 0
    return [f"{0.0 if v == 0 else v:,.{decimals}f}" for v in ticks]


X_RESOLUTION = 1e-6
"""Time is written to a millionth of the axis (1 ms on a 10-minute log)."""
Y_RESOLUTION = 2e-5
"""Values to 1/50,000 of their axis (0.1 us on a +-2.5 ms error axis): hover reads them."""


def _digits(span: float, resolution: float) -> int:
    """Decimals that resolve `resolution` of a span."""
    if not (span > 0 and math.isfinite(span)):
        return 3
    return max(0, min(9, -math.floor(math.log10(span * resolution))))


GAP_FACTOR = 5.0
"""A line breaks where consecutive points are this many median spacings apart (frames or
revolutions missing), instead of bridging the gap."""


def _path(
    x: NDArray[np.float64], y: NDArray[np.float64], xd: int, yd: int, gap: float = math.inf
) -> str:
    """SVG path data in data units (y negated), a new subpath where points are `gap` apart."""
    if x.size == 0:
        return ""
    xs = np.round(x, xd)
    ys = np.round(-y, yd) + 0.0
    text = [f"{a:.{xd}f},{b:.{yd}f}" for a, b in zip(xs.tolist(), ys.tolist(), strict=True)]
    for i in np.flatnonzero(np.diff(x) > gap).tolist():
        text[i + 1] = "M" + text[i + 1]
    return "M" + " ".join(text)


def _dots(x: NDArray[np.float64], y: NDArray[np.float64], xd: int, yd: int) -> str:
    """Zero-length subpaths (drawn as round dots by the stroke caps)."""
    xs = np.round(x, xd)
    ys = np.round(-y, yd) + 0.0
    return " ".join(
        f"M{a:.{xd}f},{b:.{yd}f} {a:.{xd}f},{b:.{yd}f}"
        for a, b in zip(xs.tolist(), ys.tolist(), strict=True)
    )


def _series_points(s: Series) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """The points to draw and the spacing beyond which the line breaks (a gap in the data)."""
    x, y = s.x_s, s.y
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if s.dots:
        return x, y, math.inf
    gap = GAP_FACTOR * float(np.median(np.diff(x))) if x.size > 2 else math.inf
    if s.step:
        sx, sy = envelope(*steps_only(x, y))
        return sx, sy, math.inf
    ex, ey = envelope(x, y)
    # An envelope's min and max of neighbouring buckets can be two buckets apart.
    gap *= max(1.0, 2.0 * x.size / max(ex.size, 1))
    return ex, ey, gap if gap > 0 else math.inf


def _extent(
    plot: TimePlot, drawn: list[tuple[NDArray[np.float64], NDArray[np.float64], float]]
) -> tuple[float, float, float, float]:
    xs = [d[0] for d in drawn if d[0].size]
    ys = [d[1] for d in drawn if d[1].size]
    x0 = min((float(a.min()) for a in xs), default=0.0)
    x1 = max((float(a.max()) for a in xs), default=1.0)
    if x1 <= x0:
        x1 = x0 + 1.0
    y_values = [float(a.min()) for a in ys] + [float(a.max()) for a in ys]
    y_values += [b.low for b in plot.bands] + [b.high for b in plot.bands]
    y_values += [v for v, _ in plot.limits]
    y_values += [0.0, 1.0] if plot.counts else []
    y_values = [v for v in y_values if math.isfinite(v)]
    y0, y1 = (min(y_values), max(y_values)) if y_values else (0.0, 1.0)
    if y1 <= y0:
        y0, y1 = y0 - 1.0, y1 + 1.0
    pad = (y1 - y0) * 0.05
    return x0, x1, y0 - pad, y1 + pad


def time_plot_svg(plot: TimePlot, *, x_range: tuple[float, float] | None = None) -> str:
    """The plot as a <figure class="tplot"> holding one SVG; `x_range` fixes the time axis."""
    drawn = [_series_points(s) for s in plot.series]
    x0, x1, y0, y1 = _extent(plot, drawn)
    if x_range is not None and x_range[1] > x_range[0]:
        x0, x1 = x_range
    w, h = plot.width, plot.height
    pw, ph = w - LEFT - RIGHT, h - TOP - BOTTOM
    xd = _digits(x1 - x0, X_RESOLUTION)
    yd = _digits(y1 - y0, Y_RESOLUTION)

    def py(v: float) -> float:
        return TOP + ph * (y1 - v) / (y1 - y0)

    def px(v: float) -> float:
        return LEFT + pw * (v - x0) / (x1 - x0)

    out = [
        f'<figure class="tplot" data-kind="{esc(plot.kind)}" data-x0="{x0:.6f}" '
        f'data-x1="{x1:.6f}" data-unit="{esc(plot.unit)}">'
        f'<figcaption>{esc(plot.title)} <span class="unit">[{esc(plot.unit)}]</span></figcaption>'
        f'<svg class="plot" width="{w}" height="{h}" viewBox="0 0 {w} {h}" role="img" '
        f'aria-label="{esc(plot.title)}">',
        f'<rect x="{LEFT}" y="{TOP}" width="{pw}" height="{ph}" fill="#fff" stroke="#bbb"/>',
    ]
    # y axis: ticks, grid, unit label
    y_ticks = nice_ticks(y0, y1)
    if plot.counts:
        y_ticks = [t for t in nice_ticks(y0, y1, 4) if t == int(t)]
    for tick, text in zip(y_ticks, tick_labels(y_ticks), strict=True):
        y = py(tick)
        out.append(
            f'<line x1="{LEFT}" x2="{LEFT + pw}" y1="{y:.1f}" y2="{y:.1f}" class="grid"/>'
            f'<text x="{LEFT - 5}" y="{y + 4:.1f}" class="yt">{esc(text)}</text>'
        )
    out.append(
        f'<text x="14" y="{TOP + ph / 2:.0f}" class="ylabel" '
        f'transform="rotate(-90 14 {TOP + ph / 2:.0f})">{esc(plot.unit)}</text>'
    )
    # x axis: ticks in seconds (the script redraws them on zoom)
    out.append(f'<g class="xt" data-y="{TOP + ph}">')
    x_ticks = nice_ticks(x0, x1, 10)
    for tick, text in zip(x_ticks, tick_labels(x_ticks), strict=True):
        x = px(tick)
        out.append(
            f'<line x1="{x:.1f}" x2="{x:.1f}" y1="{TOP}" y2="{TOP + ph}" class="grid"/>'
            f'<text x="{x:.1f}" y="{TOP + ph + 14}" class="xtick">{esc(text)}</text>'
        )
    out.append("</g>")
    out.append(
        f'<text x="{LEFT + pw / 2:.0f}" y="{h - 3}" class="xlabel">time into the log [s]</text>'
    )
    # data area in data units
    out.append(
        f'<svg class="area" x="{LEFT}" y="{TOP}" width="{pw}" height="{ph}" '
        f'viewBox="{x0:.6f} {-y1:.6g} {x1 - x0:.6f} {y1 - y0:.6g}" preserveAspectRatio="none">'
    )
    for band in plot.bands:
        out.append(
            f'<rect class="band" x="{x0 - (x1 - x0) * 10:.6g}" y="{-band.high:.6g}" '
            f'width="{(x1 - x0) * 21:.6g}" height="{band.high - band.low:.6g}" '
            f'fill="{esc(band.colour)}"><title>{esc(band.label)}</title></rect>'
        )
    for value, label in plot.limits:
        out.append(
            f'<line class="limit" x1="{x0 - (x1 - x0) * 10:.6g}" x2="{x1 + (x1 - x0) * 10:.6g}" '
            f'y1="{-value:.6g}" y2="{-value:.6g}" vector-effect="non-scaling-stroke">'
            f"<title>{esc(label)}</title></line>"
        )
    for s, (sx, sy, gap) in zip(plot.series, drawn, strict=True):
        attrs = (
            f'data-label="{esc(s.label)}" data-n="{sx.size}" stroke="{esc(s.colour)}" '
            f'vector-effect="non-scaling-stroke"'
        )
        if s.dots:
            out.append(f'<path class="dots" {attrs} d="{_dots(sx, sy, xd, yd)}"/>')
        else:
            out.append(f'<path class="line" {attrs} fill="none" d="{_path(sx, sy, xd, yd, gap)}"/>')
    out.append("</svg>")
    # legend
    lx: float = LEFT + 6
    for s in plot.series:
        label = s.label + (" (dots)" if s.dots else "")
        out.append(
            f'<rect x="{lx}" y="6" width="10" height="3" fill="{esc(s.colour)}"/>'
            f'<text x="{lx + 14}" y="11" class="legend">{esc(label)}</text>'
        )
        lx += 14 + 6.3 * len(label) + 14
    for band in plot.bands:
        out.append(
            f'<rect x="{lx}" y="2" width="10" height="10" fill="{esc(band.colour)}"/>'
            f'<text x="{lx + 14}" y="11" class="legend">{esc(band.label)}</text>'
        )
        lx += 14 + 6.3 * len(band.label) + 14
    for _, label in plot.limits:
        out.append(
            f'<line x1="{lx}" x2="{lx + 12}" y1="7" y2="7" class="limit"/>'
            f'<text x="{lx + 16}" y="11" class="legend">{esc(label)}</text>'
        )
        lx += 16 + 6.3 * len(label) + 14
    out.append("</svg></figure>")
    return "".join(out)


def histogram_svg(
    values: NDArray[np.float64],
    *,
    title: str,
    unit: str,
    limit: float | None = None,
    limit_label: str = "",
    bins: int = 40,
    width: int = 480,
    height: int = 230,
) -> str:
    """A histogram of `values` (finite ones) as a <figure class="hist">."""
    values = values[np.isfinite(values)]
    w, h = width, height
    pw, ph = w - LEFT - RIGHT, h - TOP - BOTTOM
    head = (
        f'<figure class="hist" data-kind="histogram" data-n="{values.size}">'
        f'<figcaption>{esc(title)} <span class="unit">[{esc(unit)}]</span></figcaption>'
    )
    if values.size == 0:
        return head + "<p>No values.</p></figure>"
    high = float(values.max())
    if limit is not None and math.isfinite(limit):
        high = max(high, limit * 1.05)
    low = min(0.0, float(values.min()))
    if high <= low:
        high = low + 1.0
    counts, edges = np.histogram(values, bins=bins, range=(low, high))
    top = max(int(counts.max()), 1)
    out = [
        head,
        f'<svg class="plot" width="{w}" height="{h}" viewBox="0 0 {w} {h}" role="img" '
        f'aria-label="{esc(title)}">',
        f'<rect x="{LEFT}" y="{TOP}" width="{pw}" height="{ph}" fill="#fff" stroke="#bbb"/>',
    ]

    def px(v: float) -> float:
        return LEFT + pw * (v - low) / (high - low)

    count_ticks = [t for t in nice_ticks(0, top, 4) if t == int(t)]
    for tick, text in zip(count_ticks, tick_labels(count_ticks), strict=True):
        y = TOP + ph * (1 - tick / top)
        out.append(
            f'<line x1="{LEFT}" x2="{LEFT + pw}" y1="{y:.1f}" y2="{y:.1f}" class="grid"/>'
            f'<text x="{LEFT - 5}" y="{y + 4:.1f}" class="yt">{esc(text)}</text>'
        )
    value_ticks = nice_ticks(low, high, 6)
    for tick, text in zip(value_ticks, tick_labels(value_ticks), strict=True):
        x = px(tick)
        out.append(f'<text x="{x:.1f}" y="{TOP + ph + 14}" class="xtick">{esc(text)}</text>')
    for count, a, b in zip(counts.tolist(), edges[:-1].tolist(), edges[1:].tolist(), strict=True):
        if not count:
            continue
        bh = ph * count / top
        out.append(
            f'<rect class="bar" x="{px(a):.1f}" y="{TOP + ph - bh:.1f}" '
            f'width="{max(px(b) - px(a) - 1, 1):.1f}" height="{bh:.1f}">'
            f"<title>{a:,.1f}..{b:,.1f} {esc(unit)}: {count} frames</title></rect>"
        )
    if limit is not None and math.isfinite(limit):
        x = px(limit)
        out.append(
            f'<line x1="{x:.1f}" x2="{x:.1f}" y1="{TOP}" y2="{TOP + ph}" class="limit"/>'
            f'<text x="{x + 3:.1f}" y="{TOP + 12}" class="legend">{esc(limit_label)}</text>'
        )
    out.append(
        f'<text x="{LEFT + pw / 2:.0f}" y="{h - 3}" class="xlabel">{esc(unit)}</text>'
        f'<text x="14" y="{TOP + ph / 2:.0f}" class="ylabel" '
        f'transform="rotate(-90 14 {TOP + ph / 2:.0f})">frames</text></svg></figure>'
    )
    return "".join(out)


@dataclass(frozen=True, slots=True)
class Bar:
    """One bar of a bar chart."""

    label: str
    value: float
    colour: str = COLOURS[0]


def bar_chart_svg(
    bars: Sequence[Bar],
    *,
    title: str,
    unit: str,
    limit: float | None = None,
    limit_label: str = "",
    kind: str = "bars",
    width: int = 480,
) -> str:
    """Horizontal bars (one per labelled value; NaN drawn as 'n/a') as a <figure class="bars">."""
    row = 18
    h = TOP + BOTTOM + row * max(len(bars), 1)
    left = 150
    pw = width - left - RIGHT
    finite = [b.value for b in bars if math.isfinite(b.value)]
    if limit is not None and math.isfinite(limit):
        finite.append(limit)
    high = max(finite, default=1.0) * 1.05 or 1.0
    out = [
        f'<figure class="bars" data-kind="{esc(kind)}" data-n="{len(bars)}">'
        f'<figcaption>{esc(title)} <span class="unit">[{esc(unit)}]</span></figcaption>'
        f'<svg class="plot" width="{width}" height="{h}" viewBox="0 0 {width} {h}" role="img" '
        f'aria-label="{esc(title)}">'
    ]
    bar_ticks = nice_ticks(0, high, 5)
    for tick, text in zip(bar_ticks, tick_labels(bar_ticks), strict=True):
        x = left + pw * tick / high
        out.append(
            f'<line x1="{x:.1f}" x2="{x:.1f}" y1="{TOP}" y2="{h - BOTTOM}" class="grid"/>'
            f'<text x="{x:.1f}" y="{h - BOTTOM + 14}" class="xtick">{esc(text)}</text>'
        )
    for i, bar in enumerate(bars):
        y = TOP + i * row
        out.append(f'<text x="{left - 5}" y="{y + 13}" class="yt">{esc(bar.label)}</text>')
        if math.isfinite(bar.value):
            out.append(
                f'<rect class="bar" x="{left}" y="{y + 3}" width="{pw * bar.value / high:.1f}" '
                f'height="{row - 6}" fill="{esc(bar.colour)}"><title>{esc(bar.label)}: '
                f"{bar.value:,.3g} {esc(unit)}</title></rect>"
            )
        else:
            out.append(f'<text x="{left + 4}" y="{y + 13}" class="legend">n/a</text>')
    if limit is not None and math.isfinite(limit):
        x = left + pw * limit / high
        out.append(
            f'<line x1="{x:.1f}" x2="{x:.1f}" y1="{TOP}" y2="{h - BOTTOM}" class="limit"/>'
            f'<text x="{x + 3:.1f}" y="{TOP - 4}" class="legend">{esc(limit_label)}</text>'
        )
    out.append(f'<text x="{left + pw / 2:.0f}" y="{h - 3}" class="xlabel">{esc(unit)}</text>')
    out.append("</svg></figure>")
    return "".join(out)
