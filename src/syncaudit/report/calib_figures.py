"""Figures of a calibration result: mounts, residuals, maps by stop, degenerate directions.

Drawn from `syncaudit.calib.result` data only: every LiDAR's recorded and estimated mount
from above in the reference frame, the estimate's difference against the limits, each
cross-scan pair's residual after alignment, each LiDAR's map from above coloured by stop
(`syncaudit.report.topview`), a degenerate scene's free direction (`degeneracy`), and for
each alignment refused as degenerate its weakest translation direction and rotation axis
(its structured conditioning; reasons are never parsed for numbers).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from syncaudit.calib.result import (
    AlignmentOut,
    CalibrationResult,
    DegeneracyOut,
    LidarOut,
)
from syncaudit.report.plot import COLOURS, Bar, bar_chart_svg, esc
from syncaudit.report.topview import arrow as _arrow
from syncaudit.report.topview import mounts_svg, top_view_svg


@dataclass(frozen=True, slots=True)
class Weakest:
    """The least constrained translation direction and rotation axis of an alignment."""

    label: str
    reason: str
    translation: tuple[float, float, float]
    translation_information: float
    rotation_axis: tuple[float, float, float]
    rotation_information: float

    @classmethod
    def of(cls, label: str, alignment: AlignmentOut) -> Weakest:
        """From a refused alignment's conditioning."""
        c = alignment.conditioning
        return cls(
            label,
            alignment.reason or "refused",
            c.weakest_translation,
            c.translation_information,
            c.weakest_rotation_axis,
            c.rotation_information,
        )


def degenerate_svg(w: Weakest) -> str:
    """A refused alignment's weakest translation direction (top view, z as text) and axis."""
    size, mid = 220, 110
    label, reason = w.label, w.reason
    tx, ty, tz = w.translation
    rx, ry, rz = w.rotation_axis
    return (
        f'<figure class="xy" data-kind="degenerate"><figcaption>{esc(label)}: '
        f'<span class="fail">{esc(reason)}</span> <span class="unit">[weakest directions, '
        "top view; x forward up, y left]</span></figcaption>"
        f'<svg class="plot" width="{size}" height="{size}" viewBox="0 0 {size} {size}" role="img" '
        f'aria-label="degenerate direction">'
        f'<rect x="0" y="0" width="{size}" height="{size}" fill="#fff" stroke="#bbb"/>'
        f'<circle cx="{mid}" cy="{mid}" r="80" fill="none" class="grid" stroke="#ececec"/>'
        + _arrow(mid, mid, -80 * ty, -80 * tx, "#b00020", "weak-translation")
        + _arrow(mid, mid, 80 * ty, 80 * tx, "#b00020", "weak-translation")
        + _arrow(mid, mid, -60 * ry, -60 * rx, "#9c3fbf", "weak-rotation")
        + f'<text x="6" y="{size - 22}" class="legend" fill="#b00020">translation '
        f"({tx:+.2f}, {ty:+.2f}, {tz:+.2f}) info {w.translation_information:.2g}</text>"
        f'<text x="6" y="{size - 8}" class="legend">rotation axis ({rx:+.2f}, {ry:+.2f}, '
        f"{rz:+.2f}) info {w.rotation_information:.2g}</text></svg></figure>"
    )


def _vector(v: tuple[float, float, float]) -> str:
    """(+0.18, +0.98, +0.00): signed, two decimals, no negative zero."""
    return "(" + ", ".join(f"{round(c, 2) + 0.0:+.2f}" for c in v) + ")"


def scene_degeneracy_svg(degeneracy: DegeneracyOut) -> str:
    """A degenerate scene's free direction from above, and its information against the limit.

    A translation is drawn as a double arrow along the direction the scene lets everything
    slide; a rotation as a dashed circle about the axis (its tilt as text). A direction
    that is mostly vertical shows as a ring with a dot (pointing out of the page).
    """
    size, mid, radius = 260, 120, 88
    dx, dy, dz = degeneracy.direction
    horizontal = math.hypot(dx, dy)
    colour = "#b00020"
    if degeneracy.kind == "rotation":
        drawing = (
            f'<circle class="free-rotation" cx="{mid}" cy="{mid}" r="{radius * 0.7:.0f}" '
            f'fill="none" stroke="{colour}" stroke-width="3" stroke-dasharray="10 5"/>'
            + _arrow(mid, mid, -radius * dy, -radius * dx, "#9c3fbf", "axis")
        )
    elif horizontal < 0.3:
        drawing = (
            f'<circle class="free-translation" cx="{mid}" cy="{mid}" r="12" fill="none" '
            f'stroke="{colour}" stroke-width="3"/><circle cx="{mid}" cy="{mid}" r="3" '
            f'fill="{colour}"/>'
        )
    else:
        drawing = _arrow(mid, mid, -radius * dy, -radius * dx, colour, "free-translation") + _arrow(
            mid, mid, radius * dy, radius * dx, colour, "free-translation"
        )
    ratio = degeneracy.information / degeneracy.limit if degeneracy.limit > 0 else math.nan
    bar_w = 200
    filled = bar_w * min(ratio, 2.0) / 2.0 if math.isfinite(ratio) else 0.0
    verb = "slides along" if degeneracy.kind == "translation" else "turns freely about"
    return (
        f'<figure class="xy" data-kind="scene-degeneracy" data-free="{esc(degeneracy.kind)}" '
        f'data-direction="{dx:.4f} {dy:.4f} {dz:.4f}">'
        f"<figcaption>Degenerate scene: everything {verb} {_vector(degeneracy.direction)} "
        f'in {esc(degeneracy.frame)} <span class="unit">[from above; x forward up, y left]'
        "</span></figcaption>"
        f'<svg class="plot" width="{size}" height="{size + 40}" viewBox="0 0 {size} {size + 40}" '
        'role="img" aria-label="degenerate direction of the scene">'
        f'<rect x="0" y="0" width="{size}" height="{size + 40}" fill="#fff" stroke="#bbb"/>'
        f'<circle cx="{mid}" cy="{mid}" r="{radius}" fill="none" stroke="#ececec"/>'
        f'<line x1="{mid}" y1="{mid - radius}" x2="{mid}" y2="{mid + radius}" class="grid"/>'
        f'<line x1="{mid - radius}" y1="{mid}" x2="{mid + radius}" y2="{mid}" class="grid"/>'
        f'<text x="{mid + 4}" y="{mid - radius + 10}" class="legend">+x</text>'
        f'<text x="{mid - radius + 2}" y="{mid - 4}" class="legend">+y</text>'
        + drawing
        + f'<text x="8" y="{size - 8}" class="legend">{esc(degeneracy.kind)} '
        f"{_vector(degeneracy.direction)} (x, y, z)</text>"
        f'<text x="8" y="{size + 8}" class="legend">information {degeneracy.information:.4g} '
        f"vs limit {degeneracy.limit:.4g}</text>"
        f'<rect x="8" y="{size + 16}" width="{bar_w}" height="10" fill="#f3f3f3" stroke="#bbb"/>'
        f'<rect class="information" x="8" y="{size + 16}" width="{filled:.1f}" height="10" '
        f'fill="{colour}"/><line x1="{8 + bar_w / 2}" x2="{8 + bar_w / 2}" y1="{size + 12}" '
        f'y2="{size + 30}" class="limit"/></svg></figure>'
    )


def _on_map(result: CalibrationResult, lidar: LidarOut) -> DegeneracyOut | None:
    """The scene's free direction when it can be drawn on this LiDAR's map (same frame)."""
    d = result.degeneracy
    if d is None or lidar.top_view is None:
        return None
    # "base_link at stop 3, lidar_rear placed by ...": the frame is what precedes the comma.
    return d if lidar.top_view.frame.split(",")[0].strip() == d.frame.strip() else None


def _degenerate(alignment: AlignmentOut) -> bool:
    """Refused because the scene left a direction unconstrained (not for overlap or fit)."""
    return not alignment.accepted and "degenerate" in (alignment.reason or "")


def calibration_figures(result: CalibrationResult) -> str:
    """The calibration's figures as an HTML fragment (inline SVG)."""
    parts = [mounts_svg(result)]
    if result.degeneracy is not None:
        parts.append(scene_degeneracy_svg(result.degeneracy))
    limits = result.limits
    rot = [
        Bar(e.frame_id, e.rotation_diff_deg if e.rotation_diff_deg is not None else math.nan)
        for e in result.extrinsics
    ]
    trans = [
        Bar(
            e.frame_id,
            e.translation_diff_cm if e.translation_diff_cm is not None else math.nan,
            COLOURS[1],
        )
        for e in result.extrinsics
    ]
    if result.extrinsics:
        parts.append(
            bar_chart_svg(
                rot,
                title="Estimated vs recorded: rotation",
                unit="deg",
                limit=limits.max_rotation_deg,
                limit_label="limit",
                kind="diff-rotation",
            )
            + bar_chart_svg(
                trans,
                title="Estimated vs recorded: translation",
                unit="cm",
                limit=limits.max_translation_cm,
                limit_label="limit",
                kind="diff-translation",
            )
        )
    for lidar in result.lidars:
        if not lidar.pairs:
            continue
        bars = [
            Bar(
                f"stops {p.first_stop}-{p.second_stop}",
                p.alignment.after.rmse_cm if p.alignment.after.rmse_cm is not None else math.nan,
                COLOURS[0] if p.alignment.accepted else COLOURS[4],
            )
            for p in lidar.pairs
        ]
        parts.append(
            bar_chart_svg(
                bars,
                title=f"{lidar.frame_id}: point-to-plane RMS after each pair's "
                "alignment (red: refused)",
                unit="cm",
                kind="pair-residuals",
            )
        )
        graph = [
            Bar(f"stops {p.first_stop}-{p.second_stop}", p.graph_residual_rotation_deg, COLOURS[2])
            for p in lidar.pairs
            if p.graph_residual_rotation_deg is not None
        ]
        if graph:
            parts.append(
                bar_chart_svg(
                    graph,
                    title=f"{lidar.frame_id}: pose-graph residual per pair",
                    unit="deg",
                    kind="graph-residuals",
                )
            )
    maps = [
        top_view_svg(result, lidar.frame_id, lidar.top_view, degeneracy=_on_map(result, lidar))
        for lidar in result.lidars
        if lidar.top_view is not None and lidar.top_view.stops
    ]
    if maps:
        parts.append("<h3>Each LiDAR's map from above, coloured by stop</h3>" + "".join(maps))
    refused = [
        Weakest.of(f"{e.frame_id} map-to-map at stop {m.anchor_stop}", m.alignment)
        for e in result.extrinsics
        for m in e.map_pairs
        if _degenerate(m.alignment)
    ]
    refused += [
        Weakest.of(f"{lidar.frame_id} stops {p.first_stop}-{p.second_stop}", p.alignment)
        for lidar in result.lidars
        for p in lidar.pairs
        if _degenerate(p.alignment)
    ]
    if refused:
        parts.append(
            "<h3>Alignments refused as degenerate: the directions the scene did not constrain</h3>"
        )
        parts.append("".join(degenerate_svg(w) for w in refused[:12]))
        if len(refused) > 12:
            parts.append(f"<p>… and {len(refused) - 12} more refused alignments.</p>")
    return '<div class="row calib-figures">' + "".join(parts) + "</div>"
