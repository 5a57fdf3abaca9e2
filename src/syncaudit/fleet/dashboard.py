"""`syncaudit fleet report`: a self-contained dashboard and exports from the results database.

One HTML file, everything inline (CSS, SVG plots, a few lines of script; no CDN, no
fetch): per vehicle and camera, Eq. 5 mean error, the recommended (and applied) trigger
delay (its axis scaled to the data) and t1..t4 p99 over time (log start time), the
policy limits drawn as dashed lines; a failing log's points keep their series' colour,
ringed in red and linked to its HTML report. The same per-camera table is
exported as Parquet or CSV (DuckDB's COPY) for people who use their own tools.
"""

from __future__ import annotations

import html
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from syncaudit.errors import InputOpenError, OutputError
from syncaudit.fleet.database import ResultsDB
from syncaudit.fleet.gate_outputs import OVERWRITE_HINT
from syncaudit.writers.outputs import OutputSet
from syncaudit.writers.provenance import HTML_MARK, WRITTEN_BY, refusal

EXPORT_QUERY = """
SELECT l.vehicle, c.camera, coalesce(l.start_time, l.judged_at) AS time, l.path, l.verdict,
       l.report, l.log_key, c.error_mean_us, c.error_var_us2, c.error_p99_us,
       c.delay_applied_us, c.delay_recommended_us,
       c.t1_p99_us, c.t2_p99_us, c.t3_p99_us, c.t4_p99_us,
       c.frames_total, c.frames_paired,
       (SELECT max(k.limit_max) FROM checks k WHERE k.log_key = l.log_key AND k.scope = 'camera'
          AND k.subject = c.camera AND k."check" = 'error_mean_us') AS error_mean_limit_us
FROM cameras c JOIN logs l USING (log_key)
ORDER BY l.vehicle NULLS LAST, c.camera, time, l.path
"""

_STYLE = """
body{font:14px/1.45 system-ui,sans-serif;margin:1.5rem auto;max-width:1200px;color:#222}
h1{font-size:1.4rem}h2{font-size:1.2rem;margin-top:2rem;border-bottom:1px solid #ddd}
h3{font-size:1rem;margin:1rem 0 .3rem}.plots{display:flex;flex-wrap:wrap;gap:.6rem}
figure{margin:0}figcaption{font-size:12px;color:#555}svg{border:1px solid #ddd;background:#fff}
table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:.2rem .5rem}
.fail,.error{color:#b00020;font-weight:600}.pass{color:#176f2c}.warn{color:#8a5a00}
"""

_SCRIPT = """
document.getElementById('vehicle').addEventListener('change', function (e) {
  for (const s of document.querySelectorAll('section.vehicle')) {
    s.hidden = e.target.value !== '' && s.dataset.vehicle !== e.target.value;
  }
});
document.body.dataset.ready = 'yes';
"""

COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd")


@dataclass(frozen=True, slots=True)
class Point:
    """One log's value for a plot."""

    time: datetime
    value: float
    failed: bool
    href: str | None
    label: str


def _e(value: object) -> str:
    return html.escape(str(value))


def _finite(value: Any) -> bool:
    return value is not None and isinstance(value, (int, float)) and math.isfinite(value)


def _epoch(time: datetime) -> float:
    """Seconds since the epoch of a database timestamp (naive, UTC)."""
    return time.replace(tzinfo=UTC).timestamp()


def _tick(value: float) -> str:
    return f"{value:,.0f}" if abs(value) >= 100 else f"{value:.3g}"


def plot_svg(
    title: str,
    series: Sequence[tuple[str, list[Point]]],
    *,
    unit: str,
    limit: float | None = None,
    width: int = 380,
    height: int = 200,
    zero_based: bool = True,
) -> str:
    """A small time plot: one polyline per series, a dashed limit line; a failing log's
    points keep their series' colour, ringed in red and larger.

    `zero_based=False` scales the value axis to the data (a delay of 16 ms with a 1.5 ms
    gap between its series: from 0 the gap would be a few pixels)."""
    points = [p for _, pts in series for p in pts]
    left, right, top, bottom = 62, 10, 16, 28
    if not points:
        return (
            f'<svg class="plot" width="{width}" height="{height}" role="img" aria-label="{_e(title)}">'
            f'<text x="{width / 2}" y="{height / 2}" text-anchor="middle">no data</text></svg>'
        )
    times = [_epoch(p.time) for p in points]
    values = [p.value for p in points] + ([limit] if limit is not None else [])
    t0, t1 = min(times), max(times)
    v0, v1 = (min(0.0, min(values)), max(values)) if zero_based else (min(values), max(values))
    if t1 == t0:
        t0, t1 = t0 - 1, t1 + 1
    if v1 == v0:
        v0, v1 = (v0, v0 + 1) if zero_based else (v0 - 1, v1 + 1)
    if not zero_based:
        v0 -= (v1 - v0) * 0.1
    v1 += (v1 - v0) * 0.05

    def x(t: float) -> float:
        return left + (t - t0) / (t1 - t0) * (width - left - right)

    def y(v: float) -> float:
        return height - bottom - (v - v0) / (v1 - v0) * (height - top - bottom)

    parts = [
        f'<svg class="plot" width="{width}" height="{height}" viewBox="0 0 {width} {height}" '
        f'role="img" aria-label="{_e(title)}" xmlns="http://www.w3.org/2000/svg">',
        f'<line x1="{left}" y1="{y(v0):.1f}" x2="{width - right}" y2="{y(v0):.1f}" stroke="#999"/>',
        f'<line x1="{left}" y1="{top}" x2="{left}" y2="{height - bottom}" stroke="#999"/>',
    ]
    for frac in (0.0, 0.5, 1.0):
        value = v0 + frac * (v1 - v0)
        parts.append(
            f'<text x="{left - 4}" y="{y(value) + 4:.1f}" font-size="10" text-anchor="end">{_tick(value)}</text>'
        )
    for stamp, anchor in ((t0, "start"), (t1, "end")):
        label = datetime.fromtimestamp(stamp, tz=UTC).strftime("%Y-%m-%d %H:%M")
        parts.append(
            f'<text x="{x(stamp):.1f}" y="{height - 8}" font-size="10" text-anchor="{anchor}">{label}</text>'
        )
    parts.append(
        f'<text x="{left + 4}" y="{top + 10}" font-size="10" fill="#555">{_e(unit)}</text>'
    )
    if limit is not None:
        parts.append(
            f'<line class="limit" x1="{left}" y1="{y(limit):.1f}" x2="{width - right}" '
            f'y2="{y(limit):.1f}" stroke="#b00020" stroke-dasharray="5 3"><title>policy limit '
            f"{limit:.6g} {_e(unit)}</title></line>"
        )
    for index, (name, pts) in enumerate(series):
        colour = COLOURS[index % len(COLOURS)]
        ordered = sorted(pts, key=lambda p: p.time)
        coords = " ".join(f"{x(_epoch(p.time)):.1f},{y(p.value):.1f}" for p in ordered)
        if len(ordered) > 1:
            parts.append(
                f'<polyline fill="none" stroke="{colour}" points="{coords}"><title>{_e(name)}</title></polyline>'
            )
        for p in ordered:
            ring = ' stroke="#b00020" stroke-width="2"' if p.failed else ""
            dot = (
                f'<circle class="{"failed" if p.failed else "point"}" cx="{x(_epoch(p.time)):.1f}" '
                f'cy="{y(p.value):.1f}" r="{5 if p.failed else 3}" fill="{colour}"{ring}>'
                f"<title>{_e(name)}: {p.value:.6g} {_e(unit)} — {_e(p.label)}</title></circle>"
            )
            parts.append(f'<a href="{_e(p.href)}">{dot}</a>' if p.href else dot)
    parts.append("</svg>")
    return "".join(parts)


def _legend(names: Sequence[str]) -> str:
    return " ".join(
        f'<span style="color:{COLOURS[i % len(COLOURS)]}">■ {_e(n)}</span>'
        for i, n in enumerate(names)
    )


def render_dashboard(rows: list[dict[str, Any]], html_dir: Path) -> str:
    """The dashboard page from the export query's rows."""
    groups: dict[str, dict[str, list[dict[str, Any]]]] = {}
    for row in rows:
        groups.setdefault(row["vehicle"] or "(no vehicle)", {}).setdefault(
            row["camera"], []
        ).append(row)
    sections = []
    for vehicle, cameras in groups.items():
        blocks = []
        for camera, items in cameras.items():

            def points(column: str, items: list[dict[str, Any]] = items) -> list[Point]:
                out = []
                for r in items:
                    if not _finite(r[column]) or r["time"] is None:
                        continue
                    href = None
                    if r["report"] and r["verdict"] in ("fail", "error"):
                        href = os.path.relpath(r["report"], html_dir)
                    out.append(
                        Point(
                            r["time"],
                            float(r[column]),
                            r["verdict"] == "fail",
                            href,
                            f"{r['path']} ({r['verdict']})",
                        )
                    )
                return out

            limits = [r["error_mean_limit_us"] for r in items if _finite(r["error_mean_limit_us"])]
            plots = [
                (
                    "Eq. 5 mean |error|",
                    plot_svg(
                        "Eq. 5 mean error",
                        [("error_mean_us", points("error_mean_us"))],
                        unit="us",
                        limit=limits[-1] if limits else None,
                    ),
                    "",
                ),
                (
                    "trigger delay",
                    plot_svg(
                        "trigger delay",
                        [
                            ("recommended", points("delay_recommended_us")),
                            ("applied", points("delay_applied_us")),
                        ],
                        unit="us",
                        zero_based=False,
                    ),
                    _legend(["recommended", "applied"]),
                ),
                (
                    "t1..t4 p99",
                    plot_svg(
                        "latencies p99",
                        [(f"t{i}", points(f"t{i}_p99_us")) for i in range(1, 5)],
                        unit="us",
                    ),
                    _legend([f"t{i}" for i in range(1, 5)]),
                ),
            ]
            figures = "".join(
                f"<figure>{svg}<figcaption>{_e(cap)} {legend}</figcaption></figure>"
                for cap, svg, legend in plots
            )
            failing = [r for r in items if r["verdict"] in ("fail", "error")]
            links = "".join(
                f'<li><a class="fail" href="{_e(os.path.relpath(r["report"], html_dir))}">{_e(r["path"])}</a></li>'
                if r["report"]
                else f'<li class="fail">{_e(r["path"])}</li>'
                for r in failing
            )
            fail_list = (
                f"<p>Failing logs (their points ringed in red, linked to the report):</p><ul>{links}</ul>"
                if failing
                else ""
            )
            blocks.append(
                f'<div class="camera" data-camera="{_e(camera)}"><h3>{_e(camera)} — {len(items)} log(s)</h3>'
                f'<div class="plots">{figures}</div>{fail_list}</div>'
            )
        sections.append(
            f'<section class="vehicle" data-vehicle="{_e(vehicle)}"><h2>{_e(vehicle)}</h2>{"".join(blocks)}</section>'
        )
    options = "".join(f'<option value="{_e(v)}">{_e(v)}</option>' for v in groups)
    verdicts: dict[str, int] = {}
    seen: set[str] = set()
    for row in rows:
        if row["log_key"] not in seen:
            seen.add(row["log_key"])
            verdicts[row["verdict"]] = verdicts.get(row["verdict"], 0) + 1
    counts = " · ".join(f'<span class="{v}">{n} {v}</span>' for v, n in sorted(verdicts.items()))
    body = "".join(sections) or "<p>No audited camera in the database yet.</p>"
    return (
        "<!doctype html><html lang=en><head><meta charset=utf-8>"
        + HTML_MARK
        + f"<title>syncaudit fleet dashboard</title><style>{_STYLE}</style></head><body>"
        f"<h1>syncaudit fleet dashboard</h1><p>{len(seen)} judged log(s) with cameras: {counts}</p>"
        f'<label>vehicle <select id="vehicle"><option value="">all</option>{options}</select></label>'
        f"{body}<script>{_SCRIPT}</script></body></html>\n"
    )


def _copy_to(con: Any, tmp: Path, fmt: str) -> None:
    """DuckDB COPY of the export query into `tmp` (an OutputSet temporary)."""
    mark = WRITTEN_BY.replace("'", "''")  # the mark `--overwrite` looks for (docs/outputs.md)
    options = (
        f"(FORMAT parquet, KV_METADATA {{syncaudit: '{mark}'}})"
        if fmt == "parquet"
        else "(FORMAT csv, HEADER true)"
    )
    query = EXPORT_QUERY.replace("l.report, l.log_key, ", "l.report, ")
    quoted = str(tmp).replace("'", "''")
    con.execute(f"COPY ({query}) TO '{quoted}' {options}")


def _check_dashboard_folder(html_dir: Path, index: Path) -> None:
    """An existing `--html` folder is written into only when empty or a dashboard's own."""
    if html_dir.is_symlink():
        raise OutputError(f"{html_dir}: is a symbolic link; not writing into it")
    entries = [p for p in html_dir.iterdir() if not p.name.startswith(".syncaudit-")]
    if not entries:
        return
    why = refusal(index) if index.is_file() else "holds no index.html"
    if why is not None:
        detail = f"its index.html {why}" if index.is_file() else why
        raise OutputError(
            f"{html_dir}: is an existing folder that is not a dashboard folder ({detail}); "
            "not writing into it (choose another --html folder)"
        )


def write_report(
    db_path: Path,
    *,
    html_dir: Path | None = None,
    parquet: Path | None = None,
    csv: Path | None = None,
    overwrite: bool = False,
) -> None:
    """Write the dashboard (`html_dir/index.html`) and/or the Parquet/CSV exports.

    One OutputSet: every target checked before the database is read, all committed
    together (a failure leaves no temporary and the previous files). An `html_dir` that
    does not exist is one folder output; an existing one gets its `index.html` replaced.
    """
    outputs = OutputSet(overwrite=overwrite, inputs=[db_path], overwrite_hint=OVERWRITE_HINT)
    with outputs:
        for export in (parquet, csv):
            if export is not None:
                outputs.claim(export)
        index: Path | None = None
        if html_dir is not None:
            outputs.refuse_input(html_dir)
            if html_dir.exists() and not html_dir.is_dir():
                raise OutputError(f"{html_dir}: exists and is not a directory (--html needs one)")
            if html_dir.exists():
                index = html_dir / "index.html"
                _check_dashboard_folder(html_dir, index)
                outputs.add(index)
            else:
                folder = outputs.add(html_dir, kind="dir")
                folder.mkdir()
                index = folder / "index.html"
        if not db_path.is_file():
            raise InputOpenError(
                f"{db_path}: no such results database (run syncaudit gate --db first)"
            )
        with ResultsDB(db_path).connect() as con:
            cursor = con.execute(EXPORT_QUERY)
            names = [d[0] for d in cursor.description]
            rows = [dict(zip(names, row, strict=True)) for row in cursor.fetchall()]
            for export, fmt in ((parquet, "parquet"), (csv, "csv")):
                if export is not None:
                    with outputs.writing(export) as tmp:
                        _copy_to(con, tmp, fmt)
        if html_dir is not None and index is not None:
            text = render_dashboard(rows, html_dir.resolve())
            if index.parent == html_dir:
                outputs.write_text(index, text)
            else:
                index.write_text(text, encoding="utf-8")
