"""Rich renderings of syncaudit results for the terminal."""

from __future__ import annotations

from typing import Any

from rich.console import Console
from rich.table import Table

from syncaudit.audit.inspect import InfoReport
from syncaudit.audit.run import AuditResult


def _num(value: float | None, fmt: str = "{:.1f}", missing: str = "-") -> str:
    return missing if value is None or value != value else fmt.format(value)


def render_info(report: InfoReport, console: Console) -> None:
    """The `info` view: a header line, topics, LiDARs, cameras, guesses and warnings."""
    console.print(
        f"[bold]{report.path}[/]  {report.container}  "
        f"{_num(report.duration_s, '{:.3f} s')}  {report.messages or 0} messages"
    )
    topics = Table(title="Topics", title_justify="left", expand=False)
    for col in ("topic", "type", "count", "rate Hz"):
        topics.add_column(col, justify="right" if col in ("count", "rate Hz") else "left")
    for t in report.topics:
        topics.add_row(
            t.name, t.msgtype, str(t.count if t.count is not None else "?"), _num(t.rate_hz)
        )
    console.print(topics)
    if report.lidars:
        lidars = Table(title="LiDARs (measured from packets or point clouds)", title_justify="left")
        for col in (
            "topic",
            "vendor / model",
            "RPM",
            "revs",
            "pkts/rev",
            "dropped",
            "host-sensor clock",
            "t1 p50 / p99",
        ):
            lidars.add_column(col)
        for lidar in report.lidars:
            if lidar.clock_synchronised is None:
                clock = "-"
            elif lidar.clock_synchronised:
                clock = "[green]synchronised[/]"
            else:
                clock = f"[red]NOT synchronised[/] ({_num(lidar.clock_offset_s, '{:+.6f} s')})"
            lidars.add_row(
                lidar.topic,
                f"{lidar.vendor} {lidar.model}" + (" dual" if lidar.dual_return else ""),
                _num(lidar.rpm, "{:.2f}"),
                str(lidar.revolutions),
                _num(lidar.packets_per_revolution, "{:.0f}"),
                str(lidar.dropped_packets),
                clock,
                f"{_num(lidar.t1_p50_us)} / {_num(lidar.t1_p99_us)} us",
            )
        console.print(lidars)
    if report.cameras:
        # Cameras sharing a topic are told apart by frame id: show it where any does.
        sharing = any(cam.shared_topics for cam in report.cameras)
        cams = Table(title="Cameras", title_justify="left")
        for col in (
            "camera",
            *(("frame id",) if sharing else ()),
            "frames",
            "rate Hz",
            "exposure metadata",
            "stamp",
            "trigger checkpoints",
        ):
            cams.add_column(col)
        for cam in report.cameras:
            cams.add_row(
                cam.name,
                *((cam.frame_id or "[yellow]none[/]",) if sharing else ()),
                str(cam.frames),
                _num(cam.rate_hz),
                cam.exposure_metadata or "[yellow]none[/]",
                cam.stamp_semantics,
                " ".join(str(c) for c in cam.checkpoints) or "[yellow]none[/]",
            )
        console.print(cams)
        for cam in report.cameras:
            if cam.trigger_design:
                console.print(
                    f"camera {cam.name}: trigger design {cam.trigger_design} "
                    f"({cam.trigger_design_why})"
                )
    if report.shared_topics:
        console.print(_shared_topics_table(report))
    for guess in report.guessed:
        console.print(f"[cyan]guessed[/] {guess} (pass --rig to set them)")
    if report.health:
        console.print(f"[bold]health[/] {_health_line(report.health)}", markup=True)
    for warning in report.warnings:
        console.print(f"[yellow]warning[/] {warning}")


def _health_line(health: dict[str, object]) -> str:
    """`info`'s health line: the status, then what was checked (see audit.health)."""
    parts = [str(health["status"])]
    checked = health.get("crc_checked_chunks")
    bad = health.get("bad_crc_chunks") or []
    if checked is not None:
        parts.append(f"{checked} chunk CRCs checked, {len(bad)} bad")  # type: ignore[arg-type]
    elif health.get("crc_note"):
        parts.append(str(health["crc_note"]))
    else:
        parts.append("chunk CRCs not checked (--check-crc)")
    return "; ".join(parts)


def _shared_topics_table(report: InfoReport) -> Table:
    """Topics several cameras share: the messages each camera gets, the frame ids seen."""
    table = Table(title="Topics shared by several cameras", title_justify="left")
    for col in ("topic", "kind", "messages", "per camera", "frame ids seen", "not used"):
        table.add_column(col)
    for row in report.shared_topics:
        left = {
            # Triggers naming no camera are not lost: each is offered to every camera.
            "naming no camera": row.unnamed if row.kind != "trigger" else 0,
            "naming an unknown one": sum(row.unknown.values()),
            "damaged": row.damaged,
        }
        table.add_row(
            row.topic,
            row.kind,
            str(row.messages),
            ", ".join(f"{name} {count}" for name, count in row.cameras.items()),
            ", ".join(f"{frame or '(empty)'} {count}" for frame, count in row.frame_ids.items()),
            ", ".join(f"{count} {why}" for why, count in left.items() if count) or "0",
        )
    return table


def _design_line(design: dict[str, Any]) -> str:
    """The design and what to set: `ptp_phase: shift -698.5 us -> set phase = 27.1 deg`."""
    rec = design["recommendation"]
    line = f"{design['design']}: {rec['action']}"
    if rec["action"] == "shift_trigger":
        line += f" by {_us(rec['shift_us'])} us"
    if rec.get("set") and rec["action"] == "shift_trigger":
        line += f" -> set [bold]{rec['set']['parameter']} = {rec['set']['value']}[/] {rec['set']['unit']}"
    rows = design.get("rolling_shutter")
    if rows:
        line += (
            f"; rolling shutter rows 0 / {rows['target_row']} / {rows['rows'] - 1}: "
            f"{_us(rows['top']['error_signed_mean_us'])} / "
            f"{_us(rows['target']['error_signed_mean_us'])} / "
            f"{_us(rows['bottom']['error_signed_mean_us'])} us"
        )
    return line


def _us(value: float | None, fmt: str = "{:.1f}") -> str:
    return _num(value, fmt)


ACTIONS = {
    "shift_trigger": "shift the trigger by {shift} us",
    "per_frame_compensation": "compensate per frame (exposure feed-forward)",
    "none": "leave it",
}


def advice_line(camera: str, rec: dict[str, Any]) -> str:
    """One sentence of advice for a camera, from its `recommendation` JSON object."""
    shift = rec["shift_us"]
    action = ACTIONS[rec["action"]].format(shift=_num(shift, "{:+.1f}"))
    return f"[bold]{camera}[/]: {action}: {rec['why']}"


def render_audit(result: AuditResult, console: Console) -> None:
    """The `audit` view: LiDAR side, then one table of the method's quantities per camera."""
    lidar = result.lidar
    console.print(
        f"[bold]{result.path}[/]  {result.container}  {_num(result.duration_s, '{:.3f} s')}\n"
        f"LiDAR {lidar.topic}: {lidar.vendor} {lidar.model}, {_num(lidar.rpm, '{:.2f}')} RPM, "
        f"{lidar.revolutions} revolutions, {_num(lidar.packets_per_revolution, '{:.0f}')} packets/rev, "
        f"{lidar.dropped_packets} dropped, clock "
        + (
            "synchronised"
            if lidar.clock_synchronised
            else f"[red]NOT synchronised[/] ({_num(lidar.clock_offset_s, '{:+.6f} s')})"
        )
        + f", t1 p50/p99 {_num(lidar.t1_p50_us)}/{_num(lidar.t1_p99_us)} us"
    )
    for cam in result.cameras:
        console.print(advice_line(cam.sync.camera, cam.advice.recommendation()))
    for cam in result.cameras:
        d = cam.to_dict()
        verdict = (
            f"[yellow]not judged[/] ({cam.sync.not_judged_reason})"
            if not cam.sync.judged
            else "[red]needs correction[/]"
            if cam.sync.needs_correction
            else "[green]within thresholds[/]"
        )
        table = Table(
            title=f"camera {cam.sync.camera}: {verdict}", title_justify="left", show_header=False
        )
        table.add_column("quantity")
        table.add_column("value")
        table.add_row(
            "theta / omega / t_rotate (Eq. 1)",
            f"{_num(d['theta_deg'], '{:.2f}')} deg / {_num(d['omega_deg_s'], '{:.1f}')} deg/s / "
            f"{_us(d['t_rotate_us'])} us  (azimuth from {cam.azimuth_source})",
        )
        for name, lat in d["latencies"].items():
            table.add_row(
                f"{name} mean / p50 / p99",
                f"{_us(lat['mean_us'])} / {_us(lat['p50_us'])} / "
                f"{_us(lat['p99_us'])} us  ({lat['status']})",
            )
        table.add_row("t5 mean exposure (Eq. 3)", f"{_us(d['t5_mean_us'])} us")
        table.add_row(
            "packet phase (zero crossing - packet)",
            f"{_us(d['packet_phase_us'])} us  (measured from: {d['packet_phase_source']})",
        )
        table.add_row("frames paired with triggers by", d["trigger_pairing"])
        table.add_row(
            "t_sleep applied -> recommended (Eq. 2)",
            f"{_us(d['delay_applied_us'])} -> [bold]{_us(d['delay_recommended_us'])}[/] us "
            f"(from error: {_us(d['delay_from_error_us'])} us)",
        )
        table.add_row(
            "error mean (Eq. 5) / var (Eq. 6)",
            f"{_us(d['error_mean_us'])} us / {_num(d['error_var_us2'], '{:.1f}')} us^2",
        )
        table.add_row(
            "error signed mean / p99 / max",
            f"{_us(d['error_signed_mean_us'])} / {_us(d['error_p99_us'])} / {_us(d['error_max_us'])} us",
        )
        table.add_row(
            "frames paired / total",
            f"{d['frames_paired']} / {d['frames_total']}"
            + "".join(f"; {v} {k}" for k, v in d["unpaired"].items()),
        )
        if d["corrected"]:
            c = d["corrected"]
            table.add_row(
                "with self-adaptive correction (replayed)",
                f"{c['adjustments']} adjustments, final delay {_us(c['final_delay_us'])} us; "
                f"after the first: error mean {_us(c['settled_error_mean_us'])} us, "
                f"var {_num(c['settled_error_var_us2'], '{:.1f}')} us^2",
            )
        floor = d["floor"]
        table.add_row(
            "floor (what this trigger design can reach)",
            f"Eq. 5 {_us(floor['error_mean_us'])} us; {floor['trigger']} trigger, quantisation "
            f"{_us(floor['quantisation_us'])} us std, chain jitter {_us(floor['jitter_us'])} us std",
        )
        for w in d["what_if"]:
            table.add_row(
                f"what if: {w['policy']}",
                f"Eq. 5 {_us(w['error_mean_us'])} us / Eq. 6 {_num(w['error_var_us2'], '{:.1f}')} "
                f"us^2, {w['adjustments']} adjustments",
            )
        if d["controller"]:
            k = d["controller"]
            table.add_row(
                "our controller's parameters for this log",
                f"window {k['window_frames']} frames, dead band {k['deadband_us']:.0f} us, "
                f"exposure trend gain {k['trend_gain']:g}",
            )
        if d.get("trigger_design"):
            table.add_row("trigger design -> set", _design_line(d["trigger_design"]))
        console.print(table)
        for w in cam.sync.warnings:
            console.print(f"  [yellow]warning[/] {w}")
    for item in result.missing:
        console.print(f"[yellow]missing[/] {item}")
    for guess in result.guessed:
        console.print(f"[cyan]guessed[/] {guess} (pass --rig to set them)")
    for warning in result.warnings:
        console.print(f"[yellow]warning[/] {warning}")
    for reason in result.not_judged:
        console.print(f"[yellow]not judged[/] {reason}")
    console.print(f"[bold]verdict: {result.verdict.upper()}[/]")
