"""A LiDAR's map from above, coloured by stop, with the recorded and estimated mounts on it.

Drawn from `LidarOut.top_view` (points per stop, already one per `cell_m` square) as hand
SVG like the rest of the report: equal scales on both axes with metre ticks, x forward
up and y left to the left (the view from above a vehicle heading up the page, as the
mounts figure), one colour per stop with a legend. A map beyond `MAX_MAP_POINTS` is
thinned again on a coarser grid so a report stays small. The mounts are placed when the
map's frame is one the result can relate to the reference LiDAR (see `frame_from_reference`).
"""

from __future__ import annotations

import colorsys
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from syncaudit.calib.result import CalibrationResult, DegeneracyOut, TopViewOut
from syncaudit.report.plot import esc, nice_ticks, tick_labels

MAX_MAP_POINTS = 12_000
"""Points per map beyond which the stops are thinned again on a coarser grid."""

PLOT_SIZE = 460
"""Pixels of the longer side of a map's drawing area."""
MAP_LEFT, MAP_RIGHT, MAP_TOP, MAP_BOTTOM = 58, 12, 12, 40

STOP_COLOURS = (
    "#1f77b4",
    "#ff7f0e",
    "#2ca02c",
    "#d62728",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#7f7f7f",
    "#bcbd22",
    "#17becf",
    "#393b79",
    "#ad494a",
)
"""One colour per stop (the Tableau/d3 ten and two darker ones); beyond, hues by golden angle."""

RECORDED, ESTIMATED = "#111111", "#e6007e"


def stop_colour(index: int) -> str:
    """The colour of the `index`-th stop of a map."""
    if index < len(STOP_COLOURS):
        return STOP_COLOURS[index]
    hue = (index * 0.618033988749895) % 1.0
    r, g, b = colorsys.hls_to_rgb(hue, 0.42, 0.75)
    return f"#{round(r * 255):02x}{round(g * 255):02x}{round(b * 255):02x}"


@dataclass(frozen=True, slots=True)
class StopPoints:
    """One stop's points as drawn (after any thinning)."""

    stop: int
    x_m: NDArray[np.float64]
    y_m: NDArray[np.float64]
    recorded: int
    """Points the result held for this stop."""


def _one_per_cell(
    x: NDArray[np.float64], y: NDArray[np.float64], cell_m: float
) -> NDArray[np.intp]:
    """Indices of the first point in each `cell_m` square (in the input's order)."""
    if x.size == 0:
        return np.zeros(0, dtype=np.intp)
    keys = np.stack([np.floor(x / cell_m), np.floor(y / cell_m)], axis=1).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    return np.sort(first)


def thin_stops(
    view: TopViewOut, *, max_points: int = MAX_MAP_POINTS
) -> tuple[list[StopPoints], float]:
    """Every stop's finite points, thinned on one coarser grid (per stop) when the map holds
    more than `max_points`; the cell size used (the view's own when nothing was thinned)."""
    raw = []
    for stop in view.stops:
        x = np.asarray(stop.x_m, dtype=np.float64)
        y = np.asarray(stop.y_m, dtype=np.float64)
        n = min(x.size, y.size)
        x, y = x[:n], y[:n]
        ok = np.isfinite(x) & np.isfinite(y)
        raw.append((stop.stop, x[ok], y[ok], n))
    cell = view.cell_m if view.cell_m > 0 else 0.05
    total = sum(x.size for _, x, _, _ in raw)
    out = [StopPoints(s, x, y, n) for s, x, y, n in raw]
    while total > max_points:
        # Points per stop shrink about with the square of the cell (surfaces seen from above).
        cell *= max(1.1, math.sqrt(total / max_points))
        out = []
        for s, x, y, n in raw:
            keep = _one_per_cell(x, y, cell)
            out.append(StopPoints(s, x[keep], y[keep], n))
        total = sum(p.x_m.size for p in out)
    return out, cell


@dataclass(frozen=True, slots=True)
class Mount:
    """A LiDAR's mount as placed on a map: position and yaw in the map's frame."""

    name: str
    kind: str
    """'recorded' or 'estimated' ('reference' for the reference LiDAR itself)."""
    x_m: float
    y_m: float
    yaw_rad: float


def _matrix(rows: Sequence[Sequence[float]]) -> NDArray[np.float64]:
    return np.asarray(rows, dtype=np.float64).reshape(4, 4)


def frame_from_reference(result: CalibrationResult, frame: str) -> NDArray[np.float64] | None:
    """The reference LiDAR's pose in a map's `frame` ("<frame id> at stop k[, ...]"), or None.

    A map in the reference LiDAR's own frame holds it at the origin; one in another LiDAR's
    frame holds it where the inverse of that LiDAR's recorded extrinsic puts it; one in the
    base frame (at whichever stop: the mount does not move) at `result.reference_mount`,
    the recorded base_from_reference. Without that, a base-frame map gets no mounts.
    """
    name = frame.split(",")[0].split(" at ")[0].strip()
    if name == result.reference_frame_id:
        return np.eye(4)
    for ext in result.extrinsics:
        if ext.frame_id == name:
            return np.asarray(np.linalg.inv(_matrix(ext.recorded.matrix)), dtype=np.float64)
    if name == result.base_frame and result.reference_mount is not None:
        return _matrix(result.reference_mount.matrix)
    return None


def mounts_on_map(result: CalibrationResult, frame: str) -> list[Mount]:
    """Every LiDAR's recorded and estimated mount in a map's frame ([] when not relatable)."""
    placed = frame_from_reference(result, frame)
    if placed is None:
        return []
    mounts = [_mount(result.reference_frame_id, "reference", placed)]
    for ext in result.extrinsics:
        for kind, transform in (("recorded", ext.recorded), ("estimated", ext.result)):
            if transform is not None:
                mounts.append(_mount(ext.frame_id, kind, placed @ _matrix(transform.matrix)))
    return mounts


def _mount(name: str, kind: str, pose: NDArray[np.float64]) -> Mount:
    yaw = math.atan2(float(pose[1, 0]), float(pose[0, 0]))
    return Mount(name, kind, float(pose[0, 3]), float(pose[1, 3]), yaw)


@dataclass(frozen=True, slots=True)
class _Frame:
    """Equal-scale screen placement of a map: x forward up, y left to the left."""

    x_low: float
    x_high: float
    y_low: float
    y_high: float
    px_per_m: float
    width: int
    height: int

    def screen(self, x_m: float, y_m: float) -> tuple[float, float]:
        return (
            MAP_LEFT + (self.y_high - y_m) * self.px_per_m,
            MAP_TOP + (self.x_high - x_m) * self.px_per_m,
        )


def _frame(xs: list[float], ys: list[float], *, size: int = PLOT_SIZE, pad: float = 0.04) -> _Frame:
    """Equal scales fitting the points, `pad` of the longer span around them."""
    x_low, x_high = min(xs), max(xs)
    y_low, y_high = min(ys), max(ys)
    span = max(x_high - x_low, y_high - y_low, 1.0)
    margin = span * pad
    x_low, x_high, y_low, y_high = x_low - margin, x_high + margin, y_low - margin, y_high + margin
    scale = size / max(x_high - x_low, y_high - y_low)
    return _Frame(
        x_low,
        x_high,
        y_low,
        y_high,
        scale,
        round((y_high - y_low) * scale),
        round((x_high - x_low) * scale),
    )


def _axis_ticks(frame: _Frame) -> tuple[list[float], list[float]]:
    """Metre ticks with one step for both axes (the scales are equal)."""
    longest = nice_ticks(0.0, max(frame.x_high - frame.x_low, frame.y_high - frame.y_low), count=6)
    step = longest[1] - longest[0] if len(longest) > 1 else 1.0

    def ticks(low: float, high: float) -> list[float]:
        first = math.ceil(low / step)
        return [k * step + 0.0 for k in range(first, math.floor(high / step) + 1)]

    return ticks(frame.x_low, frame.x_high), ticks(frame.y_low, frame.y_high)


def _decimals(cell_m: float) -> int:
    """Decimals that write a point to a fifth of a cell (1 cm for a 5 cm grid)."""
    return max(0, min(4, -math.floor(math.log10(max(cell_m, 1e-4) / 5))))


def _dots_path(x_m: NDArray[np.float64], y_m: NDArray[np.float64], decimals: int) -> str:
    """Zero-length subpaths at (-y, -x) (the map's data units), drawn as dots by round caps."""
    us = np.round(-y_m, decimals) + 0.0
    vs = np.round(-x_m, decimals) + 0.0
    return "".join(
        f"M{u:.{decimals}f},{v:.{decimals}f}h0"
        for u, v in zip(us.tolist(), vs.tolist(), strict=True)
    )


def arrow(x: float, y: float, dx: float, dy: float, colour: str, cls: str, width: float = 2) -> str:
    """A line with a head, screen units."""
    end_x, end_y = x + dx, y + dy
    length = math.hypot(dx, dy) or 1.0
    ux, uy = dx / length, dy / length
    left = (end_x - 8 * ux + 4 * uy, end_y - 8 * uy - 4 * ux)
    right = (end_x - 8 * ux - 4 * uy, end_y - 8 * uy + 4 * ux)
    return (
        f'<g class="{cls}"><line x1="{x:.1f}" y1="{y:.1f}" x2="{end_x:.1f}" y2="{end_y:.1f}" '
        f'stroke="{colour}" stroke-width="{width}"/><polygon points="{end_x:.1f},{end_y:.1f} '
        f'{left[0]:.1f},{left[1]:.1f} {right[0]:.1f},{right[1]:.1f}" fill="{colour}"/></g>'
    )


def _mount_mark(frame: _Frame, mount: Mount) -> str:
    """A ring (recorded), a disc (estimated) or a square (reference) with a yaw arrow."""
    x, y = frame.screen(mount.x_m, mount.y_m)
    colour = ESTIMATED if mount.kind == "estimated" else RECORDED
    title = (
        f"<title>{esc(mount.name)} {mount.kind}: x {mount.x_m:.3f} m, y {mount.y_m:.3f} m, "
        f"yaw {math.degrees(mount.yaw_rad):.2f} deg</title>"
    )
    if mount.kind == "reference":
        shape = f'<rect x="{x - 5:.1f}" y="{y - 5:.1f}" width="10" height="10" fill="{colour}">'
        shape += title + "</rect>"
    elif mount.kind == "recorded":
        shape = f'<circle cx="{x:.1f}" cy="{y:.1f}" r="6" fill="#fff" stroke="{colour}" stroke-width="2">'
        shape += title + "</circle>"
    else:
        shape = f'<circle cx="{x:.1f}" cy="{y:.1f}" r="4" fill="{colour}">{title}</circle>'
    # Yaw: x forward is up the page, y left is left.
    dx, dy = -22 * math.sin(mount.yaw_rad), -22 * math.cos(mount.yaw_rad)
    return (
        f'<g class="mount" data-name="{esc(mount.name)}" data-mount="{mount.kind}" '
        f'data-x-m="{mount.x_m:.4f}" data-y-m="{mount.y_m:.4f}">'
        + shape
        + arrow(x, y, dx, dy, colour, "yaw", 1.5)
        + "</g>"
    )


def direction_arrows(frame: _Frame, degeneracy: DegeneracyOut, origin: tuple[float, float]) -> str:
    """The free direction of a degenerate scene drawn on a map from `origin` (metres)."""
    ox, oy = frame.screen(*origin)
    dx, dy, _ = degeneracy.direction
    length = 0.3 * PLOT_SIZE
    if degeneracy.kind == "rotation":
        return (
            f'<circle class="free-rotation" cx="{ox:.1f}" cy="{oy:.1f}" r="{length / 2:.1f}" '
            'fill="none" stroke="#b00020" stroke-width="3" stroke-dasharray="10 5"/>'
        )
    sx, sy = -dy * length, -dx * length  # screen right is -y, down is -x
    return arrow(ox, oy, sx, sy, "#b00020", "free-translation", 3) + arrow(
        ox, oy, -sx, -sy, "#b00020", "free-translation", 3
    )


def _axes(frame: _Frame) -> list[str]:
    """Metre grid, ticks and axis labels of a map (x forward up, y left to the left)."""
    w, h = frame.width, frame.height
    out = []
    x_ticks, y_ticks = _axis_ticks(frame)
    for tick, text in zip(x_ticks, tick_labels(x_ticks), strict=True):
        _, sy = frame.screen(tick, 0.0)
        out.append(
            f'<line x1="{MAP_LEFT}" x2="{MAP_LEFT + w}" y1="{sy:.1f}" y2="{sy:.1f}" class="grid"/>'
            f'<text x="{MAP_LEFT - 5}" y="{sy + 4:.1f}" class="yt">{esc(text)}</text>'
        )
    for tick, text in zip(y_ticks, tick_labels(y_ticks), strict=True):
        sx, _ = frame.screen(0.0, tick)
        out.append(
            f'<line x1="{sx:.1f}" x2="{sx:.1f}" y1="{MAP_TOP}" y2="{MAP_TOP + h}" class="grid"/>'
            f'<text x="{sx:.1f}" y="{MAP_TOP + h + 14}" class="xtick">{esc(text)}</text>'
        )
    out.append(
        f'<text x="{MAP_LEFT + w / 2:.0f}" y="{MAP_TOP + h + MAP_BOTTOM - 6}" class="xlabel">'
        "y, left [m] (grows to the left)</text>"
        f'<text x="14" y="{MAP_TOP + h / 2:.0f}" class="ylabel" '
        f'transform="rotate(-90 14 {MAP_TOP + h / 2:.0f})">x, forward [m]</text>'
    )
    return out


def mounts_svg(result: CalibrationResult) -> str:
    """Every LiDAR's mount from above in the reference LiDAR's frame: recorded, estimated."""
    mounts = mounts_on_map(result, result.reference_frame_id)
    xs, ys = [m.x_m for m in mounts], [m.y_m for m in mounts]
    # A square view centred on the mounts (they often stand in a line).
    half = max(max(xs) - min(xs), max(ys) - min(ys), 1.0) / 2
    cx, cy = (max(xs) + min(xs)) / 2, (max(ys) + min(ys)) / 2
    frame = _frame([cx - half, cx + half], [cy - half, cy + half], size=300, pad=0.3)
    w, h = frame.width, frame.height
    total_w, total_h = MAP_LEFT + w + MAP_RIGHT, MAP_TOP + h + MAP_BOTTOM
    names = []
    for m in mounts:
        if m.kind in ("reference", "recorded"):
            x, y = frame.screen(m.x_m, m.y_m)
            names.append(
                f'<text x="{x + 9:.1f}" y="{y + 16:.1f}" class="legend">{esc(m.name)}</text>'
            )
    return (
        f'<figure class="xy" data-kind="mounts" data-n="{len(result.extrinsics)}">'
        "<figcaption>Mounts in the reference LiDAR's frame, from above "
        f'<span class="unit">[m, equal scales; in {esc(result.reference_frame_id)}; x forward up, '
        "y left; arrow = yaw]</span></figcaption>"
        f'<div class="row"><svg class="plot map" width="{total_w}" height="{total_h}" '
        f'viewBox="0 0 {total_w} {total_h}" role="img" aria-label="mounts from above">'
        f'<rect x="{MAP_LEFT}" y="{MAP_TOP}" width="{w}" height="{h}" fill="#fff" stroke="#bbb"/>'
        + "".join(_axes(frame))
        + "".join(_mount_mark(frame, m) for m in mounts)
        + "".join(names)
        + "</svg>"
        + _legend([], mounts, None)
        + "</div></figure>"
    )


def top_view_svg(
    result: CalibrationResult,
    frame_id: str,
    view: TopViewOut,
    *,
    max_points: int = MAX_MAP_POINTS,
    degeneracy: DegeneracyOut | None = None,
) -> str:
    """One LiDAR's map from above as a <figure class="xy" data-kind="top-view">."""
    stops, cell = thin_stops(view, max_points=max_points)
    mounts = mounts_on_map(result, view.frame)
    xs = [float(v) for p in stops if p.x_m.size for v in (p.x_m.min(), p.x_m.max())]
    ys = [float(v) for p in stops if p.y_m.size for v in (p.y_m.min(), p.y_m.max())]
    xs += [m.x_m for m in mounts] or [0.0]
    ys += [m.y_m for m in mounts] or [0.0]
    frame = _frame(xs, ys)
    w, h = frame.width, frame.height
    total_w, total_h = MAP_LEFT + w + MAP_RIGHT, MAP_TOP + h + MAP_BOTTOM
    drawn = sum(p.x_m.size for p in stops)
    held = sum(p.recorded for p in stops)
    thinned = (
        f"; thinned to one point per {cell * 100:.0f} cm square: {drawn:,} of {held:,} points"
        if cell > view.cell_m
        else f"; one point per {view.cell_m * 100:.0f} cm square, {drawn:,} points"
    )
    out = [
        f'<figure class="xy" data-kind="top-view" data-lidar="{esc(frame_id)}" '
        f'data-n="{drawn}" data-stops="{len(stops)}" data-cell-m="{cell:.4g}">'
        f"<figcaption>{esc(frame_id)}: map from above, coloured by stop "
        f'<span class="unit">[m, equal scales; in {esc(view.frame)}; x forward up, y left'
        f"{esc(thinned)}]</span></figcaption>"
        f'<div class="row"><svg class="plot map" width="{total_w}" height="{total_h}" '
        f'viewBox="0 0 {total_w} {total_h}" role="img" aria-label="{esc(frame_id)} map from above">',
        f'<rect x="{MAP_LEFT}" y="{MAP_TOP}" width="{w}" height="{h}" fill="#fff" stroke="#bbb"/>',
    ]
    out += _axes(frame)
    # The points in metres: u = -y, v = -x, so the viewBox maps them at the same scale.
    out.append(
        f'<svg class="points" x="{MAP_LEFT}" y="{MAP_TOP}" width="{w}" height="{h}" '
        f'viewBox="{-frame.y_high:.4f} {-frame.x_high:.4f} {frame.y_high - frame.y_low:.4f} '
        f'{frame.x_high - frame.x_low:.4f}" preserveAspectRatio="none">'
    )
    decimals = _decimals(cell)
    for i, stop in enumerate(stops):
        out.append(
            f'<path class="stop" data-stop="{stop.stop}" data-n="{stop.x_m.size}" '
            f'stroke="{stop_colour(i)}" vector-effect="non-scaling-stroke" '
            f'd="{_dots_path(stop.x_m, stop.y_m, decimals)}"/>'
        )
    out.append("</svg>")
    if degeneracy is not None:
        origin = next(((m.x_m, m.y_m) for m in mounts if m.kind == "reference"), (0.0, 0.0))
        out.append(direction_arrows(frame, degeneracy, origin))
    out += [_mount_mark(frame, m) for m in mounts]
    out.append("</svg>")
    out.append(_legend(stops, mounts, degeneracy))
    out.append("</div></figure>")
    return "".join(out)


def _legend(stops: list[StopPoints], mounts: list[Mount], degeneracy: DegeneracyOut | None) -> str:
    """The stops' colours and the mount marks, as an HTML list beside the map."""
    items = [
        f'<li data-stop="{p.stop}"><span class="swatch" style="background:{stop_colour(i)}">'
        f"</span>stop {p.stop} <span class=unit>({p.x_m.size:,} points)</span></li>"
        for i, p in enumerate(stops)
    ]
    if mounts:
        items += [
            f'<li><span class="mark ref" style="background:{RECORDED}"></span>reference LiDAR '
            f"{esc(mounts[0].name)}</li>",
            f'<li><span class="mark ring" style="border-color:{RECORDED}"></span>recorded mount</li>',
            f'<li><span class="mark disc" style="background:{ESTIMATED}"></span>estimated mount</li>',
            "<li class=unit>arrow: yaw (x axis of the LiDAR)</li>",
        ]
    else:
        items.append(
            "<li class=unit>mounts not drawn: the map is not in a LiDAR's frame, and the result "
            "does not give the reference LiDAR's mount on the base (reference_mount)</li>"
        )
    if degeneracy is not None:
        items.append(
            '<li><span class="mark bar" style="background:#b00020"></span>'
            f"unconstrained {esc(degeneracy.kind)}</li>"
        )
    return f'<ul class="legend-list">{"".join(items)}</ul>'
