"""Rich renderings of syncaudit results for the terminal."""

from __future__ import annotations

from rich.console import Console
from rich.table import Table

from syncaudit.inspect_log import InfoReport


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
        topics.add_row(t.name, t.msgtype, str(t.count if t.count is not None else "?"), _num(t.rate_hz))
    console.print(topics)
    if report.lidars:
        lidars = Table(title="LiDARs (measured from packets)", title_justify="left")
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
                clock = f"[red]NOT synchronised[/] ({_num(lidar.clock_offset_s, '{:+.3f} s')})"
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
        cams = Table(title="Cameras", title_justify="left")
        for col in ("camera", "frames", "rate Hz", "exposure metadata", "stamp", "trigger checkpoints"):
            cams.add_column(col)
        for cam in report.cameras:
            cams.add_row(
                cam.name,
                str(cam.frames),
                _num(cam.rate_hz),
                cam.exposure_metadata or "[yellow]none[/]",
                cam.stamp_semantics,
                " ".join(str(c) for c in cam.checkpoints) or "[yellow]none[/]",
            )
        console.print(cams)
    for guess in report.guessed:
        console.print(f"[cyan]guessed[/] {guess} (pass --rig to set them)")
    for warning in report.warnings:
        console.print(f"[yellow]warning[/] {warning}")
