"""Rendering a calibration result: a self-contained HTML fragment and rich console tables."""

from __future__ import annotations

from html import escape

from rich.console import Console
from rich.table import Table

from syncaudit.calib.result import AlignmentOut, CalibrationResult, ExtrinsicOut, FitOut, LidarOut
from syncaudit.report.calib_figures import calibration_figures

_STYLE = """
<style>
.sa-calib{font-family:system-ui,sans-serif;font-size:14px;color:#222}
.sa-calib table{border-collapse:collapse;margin:.4em 0 1em}
.sa-calib th,.sa-calib td{border:1px solid #ccc;padding:2px 6px;text-align:right}
.sa-calib th{background:#f3f3f3}
.sa-calib td.l,.sa-calib th.l{text-align:left}
.sa-calib .pass{color:#176f2c;font-weight:600}
.sa-calib .fail{color:#b00020;font-weight:600}
.sa-calib .warn{color:#9a6700;font-weight:600}
.sa-calib .muted{color:#777}
.sa-calib details{margin:.3em 0}
</style>
"""


def _num(value: float | None, digits: int = 3) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _pct(value: float | None) -> str:
    return "-" if value is None else f"{value * 100:.0f}%"


def _fit_change(before: FitOut, after: FitOut) -> tuple[str, str]:
    """'before → after' of overlap and RMSE."""
    return (
        f"{_pct(before.overlap)} → {_pct(after.overlap)}",
        f"{_num(before.rmse_cm, 2)} → {_num(after.rmse_cm, 2)}",
    )


def _verdict(result: CalibrationResult) -> tuple[str, str]:
    if not result.calibratable:
        return "warn", "NOT CALIBRATABLE"
    return ("pass", "PASS") if result.passed else ("fail", "FAIL")


def _at_stop(result: CalibrationResult) -> str:
    """Where the reference LiDAR's map is anchored: `at stop 3`, or why there is no stop."""
    if result.reference_stop is None:
        return "(no stop anchored: not calibrated)"
    return f"at stop {result.reference_stop}"


def _xyz_rpy(values: tuple[float, float, float], digits: int) -> str:
    return ", ".join(f"{v:.{digits}f}" for v in values)


def estimate_source(result: CalibrationResult, ext: ExtrinsicOut) -> str:
    """Which estimate a calibrated extrinsic is, and the joint graph's 1-sigma (its
    largest, rotation and translation) where it is the joint one."""
    joint = result.joint
    if joint is None:
        return "per-LiDAR graphs and map-to-map alignment"
    method = next((s.method for s in joint.selection if s.topic == ext.topic), "joint")
    if method == "baseline":
        return "per-LiDAR graphs and map-to-map alignment (the baseline)"
    out = next((x for x in joint.lidars if x.extrinsic.topic == ext.topic), None)
    if out is None:
        return "joint graph"
    return f"joint graph, 1-sigma {out.sigma_deg:.3f} deg / {out.sigma_cm:.2f} cm"


def _extrinsic_rows(result: CalibrationResult) -> str:
    rows = []
    for ext in result.extrinsics:
        m2m = ext.map_to_map
        overlap, rmse = _fit_change(m2m.before, m2m.after) if m2m else ("-", "-")
        if ext.calibrated:
            verdict = (
                '<span class="pass">pass</span>' if ext.passed else '<span class="fail">fail</span>'
            )
        else:
            verdict = '<span class="warn">not calibrated</span>'
        calibrated = ext.result
        rows.append(
            "<tr>"
            f'<td class="l">{escape(ext.frame_id)}<br><span class="muted">{escape(ext.topic)}</span></td>'
            f"<td>{_xyz_rpy(calibrated.translation_m, 4) if calibrated else '-'}</td>"
            f"<td>{_xyz_rpy(calibrated.rpy_deg, 3) if calibrated else '-'}</td>"
            f"<td>{_xyz_rpy(ext.recorded.translation_m, 4)}</td>"
            f"<td>{_xyz_rpy(ext.recorded.rpy_deg, 3)}</td>"
            f"<td>{_num(ext.rotation_diff_deg)}</td>"
            f"<td>{_num(ext.translation_diff_cm, 2)}</td>"
            f"<td>{overlap}</td><td>{rmse}</td>"
            f"<td>{_num(ext.hand_eye_rotation_residual_deg)}</td>"
            f'<td class="l">{verdict}'
            + (
                f'<br><span class="muted">{escape(estimate_source(result, ext))}</span>'
                if calibrated
                else ""
            )
            + (f'<br><span class="muted">{escape(ext.reason)}</span>' if ext.reason else "")
            + "</td></tr>"
        )
    return "".join(rows)


def _alignment_cells(alignment: AlignmentOut) -> str:
    overlap, rmse = _fit_change(alignment.before, alignment.after)
    cond = alignment.conditioning
    verdict = (
        '<span class="pass">accepted</span>'
        if alignment.accepted
        else f'<span class="fail">rejected</span> <span class="muted">{escape(alignment.reason or "")}</span>'
    )
    return (
        f"<td>{overlap}</td><td>{rmse}</td>"
        f"<td>{cond.translation_information:.3f} / {cond.rotation_information:.3f}</td>"
        f'<td class="l">{verdict}</td>'
    )


def _map_pair_rows(result: CalibrationResult) -> str:
    rows = []
    for ext in result.extrinsics:
        for pair in ext.map_pairs:
            rows.append(
                "<tr>"
                f'<td class="l">{escape(ext.frame_id)}</td><td>{pair.anchor_stop}</td>'
                f"<td>{len(pair.reference_stops)} / {len(pair.lidar_stops)}</td>"
                + _alignment_cells(pair.alignment)
                + "</tr>"
            )
    return "".join(rows)


def _lidar_block(lidar: LidarOut) -> str:
    used = sum(1 for s in lidar.stops if s.used)
    accepted = sum(1 for p in lidar.pairs if p.alignment.accepted)
    status = (
        f'<span class="pass">aligned</span>, local map {lidar.map_points} points'
        if lidar.aligned
        else f'<span class="warn">not aligned</span> <span class="muted">{escape(lidar.reason or "")}</span>'
    )
    stops = "".join(
        "<tr>"
        f"<td>{s.stop}</td><td>{s.stamp_ns / 1e9:.3f}</td><td>{s.static_scans}</td>"
        f"<td>{_num(s.angle_deg, 1)}</td>"
        f'<td class="l">{"used" if s.used else escape(s.reason or "not used")}</td>'
        "</tr>"
        for s in lidar.stops
    )
    pairs = "".join(
        "<tr>"
        f"<td>{p.first_stop}-{p.second_stop}</td><td>{p.separation_deg:.1f}</td>"
        f"<td>{_pct(p.predicted_overlap)}</td>"
        + _alignment_cells(p.alignment)
        + f"<td>{_num(p.graph_residual_rotation_deg)} / {_num(p.graph_residual_translation_cm, 2)}"
        + (' <span class="fail">outlier</span>' if p.graph_outlier else "")
        + "</td></tr>"
        for p in lidar.pairs
    )
    graph = lidar.pose_graph
    graph_line = (
        f"{graph.graphs} pose graph(s): {graph.nodes} stops, {graph.edges} edges, "
        f"{graph.outlier_edges} outliers, "
        f"cost {graph.error_before:.3g} → {graph.error_after:.3g}"
        if graph
        else "no pose graph"
    )
    return (
        f"<h4>{escape(lidar.frame_id)} <span class='muted'>{escape(lidar.topic)}</span></h4>"
        f"<p>{status}; {used} of {len(lidar.stops)} stops used, {accepted} of {len(lidar.pairs)} "
        f"pair alignments accepted; {graph_line}; horizontal view {_num(lidar.horizontal_fov_deg, 0)} deg; "
        f"turn axis vs recorded vertical {_num(lidar.turn_axis_vs_recorded_deg)} deg</p>"
        "<details><summary>Stops</summary><table><tr><th>stop</th><th>stamp (s)</th>"
        "<th>static scans</th><th>angle (deg)</th><th class='l'>use</th></tr>"
        f"{stops}</table></details>"
        "<details open><summary>Cross-scan alignments</summary><table><tr><th>stops</th>"
        "<th>apart (deg)</th><th>predicted overlap</th><th>overlap before → after</th>"
        "<th>error (cm) before → after</th><th>information t / r</th><th class='l'>verdict</th>"
        "<th>graph residual (deg / cm)</th></tr>"
        f"{pairs}</table></details>"
    )


def html_section(result: CalibrationResult) -> str:
    """The calibration's part of a report page: tables and figures (inline style, no script)."""
    css, label = _verdict(result)
    limits = result.limits
    notes = "".join(f"<li>{escape(n)}</li>" for n in result.notes)
    timings = ", ".join(f"{k} {v:.1f} s" for k, v in result.timings_s.items())
    libs = ", ".join(f"{escape(k)} {escape(v)}" for k, v in result.libraries.items())
    reason = f'<p class="warn">{escape(result.reason)}</p>' if result.reason else ""
    return (
        '<section class="sa-calib">'
        + _STYLE
        + f'<h3>LiDAR extrinsic calibration (non-overlapping views) <span class="{css}">{label}</span></h3>'
        + reason
        + f"<p>Log <code>{escape(result.log)}</code>; reference LiDAR "
        f"<code>{escape(result.reference_frame_id)}</code> {_at_stop(result)}; "
        f"recorded extrinsics from <code>{escape(result.extrinsics_source)}</code> "
        f"(base <code>{escape(result.base_frame)}</code>); limits {limits.max_rotation_deg:g} deg, "
        f"{limits.max_translation_cm:g} cm. Transforms are reference_from_lidar "
        "(translation m; roll, pitch, yaw deg).</p>"
        "<table><tr><th class='l'>LiDAR</th><th>calibrated xyz</th><th>calibrated rpy</th>"
        "<th>recorded xyz</th><th>recorded rpy</th><th>Δ rotation (deg)</th>"
        "<th>Δ translation (cm)</th><th>map overlap before → after</th>"
        "<th>map error (cm) before → after</th><th>hand-eye (deg)</th><th class='l'>verdict</th></tr>"
        + _extrinsic_rows(result)
        + "</table>"
        + "<details open><summary>Map-to-map alignments (local maps anchored at a shared stop;"
        " accepted ones are fused)</summary><table><tr><th class='l'>LiDAR</th><th>anchor stop</th>"
        "<th>stops in maps (reference / LiDAR)</th><th>overlap before → after</th>"
        "<th>error (cm) before → after</th><th>information t / r</th><th class='l'>verdict</th></tr>"
        + _map_pair_rows(result)
        + "</table></details>"
        + "".join(_lidar_block(lidar) for lidar in result.lidars)
        + calibration_figures(result)
        + (f"<ul>{notes}</ul>" if notes else "")
        + f'<p class="muted">{escape(timings)}; {libs}</p>'
        "</section>"
    )


def _extrinsic_table(extrinsics: list[ExtrinsicOut]) -> Table:
    table = Table(title="Extrinsics vs recorded (reference_from_lidar)")
    for col in ("LiDAR", "Δrot (deg)", "Δtrans (cm)", "map error (cm)", "verdict"):
        table.add_column(col, justify="left" if col in ("LiDAR", "verdict") else "right")
    for ext in extrinsics:
        m2m = ext.map_to_map
        if ext.calibrated:
            verdict = "[green]pass[/]" if ext.passed else "[red]fail[/]"
        else:
            verdict = "[yellow]not calibrated[/]"
        table.add_row(
            ext.frame_id,
            _num(ext.rotation_diff_deg),
            _num(ext.translation_diff_cm, 2),
            f"{_num(m2m.before.rmse_cm, 2)} → {_num(m2m.after.rmse_cm, 2)}" if m2m else "-",
            verdict,
        )
    return table


def render_calibration(result: CalibrationResult, console: Console) -> None:
    """Print the result as rich tables: verdict, extrinsics, per-LiDAR alignment summary."""
    css, label = _verdict(result)
    colour = {"pass": "green", "fail": "red", "warn": "yellow"}[css]
    console.print(f"[bold]LiDAR calibration[/] {result.log}: [bold {colour}]{label}[/]")
    if result.reason:
        console.print(f"[yellow]{result.reason}[/]")
    console.print(
        f"reference {result.reference_frame_id} {_at_stop(result)}; recorded "
        f"extrinsics from {result.extrinsics_source}; limits {result.limits.max_rotation_deg:g} deg / "
        f"{result.limits.max_translation_cm:g} cm"
    )
    console.print(_extrinsic_table(result.extrinsics))
    for ext in result.extrinsics:
        if ext.result is not None:
            console.print(
                f"{ext.frame_id}: calibrated xyz {_xyz_rpy(ext.result.translation_m, 4)} m, "
                f"rpy {_xyz_rpy(ext.result.rpy_deg, 3)} deg; recorded xyz "
                f"{_xyz_rpy(ext.recorded.translation_m, 4)} m, rpy "
                f"{_xyz_rpy(ext.recorded.rpy_deg, 3)} deg; "
                f"estimate: {estimate_source(result, ext)}"
            )
        elif ext.reason:
            console.print(f"[yellow]{ext.frame_id}: {ext.reason}[/]")
    table = Table(title="Per LiDAR")
    for col in ("LiDAR", "stops used", "pairs accepted", "graph outliers", "map points", "status"):
        table.add_column(col, justify="left" if col in ("LiDAR", "status") else "right")
    for lidar in result.lidars:
        table.add_row(
            lidar.frame_id,
            f"{sum(1 for s in lidar.stops if s.used)}/{len(lidar.stops)}",
            f"{sum(1 for p in lidar.pairs if p.alignment.accepted)}/{len(lidar.pairs)}",
            str(lidar.pose_graph.outlier_edges) if lidar.pose_graph else "-",
            str(lidar.map_points),
            "aligned" if lidar.aligned else f"[yellow]{lidar.reason or 'not aligned'}[/]",
        )
    console.print(table)
    for note in result.notes:
        console.print(f"[dim]note: {note}[/]")
