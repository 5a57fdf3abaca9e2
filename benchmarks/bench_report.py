"""Size and browser render time of the HTML report, and of the same plots in Plotly / Vega-Lite.

    python benchmarks/bench_report.py LOG [--rig RIG] [--cameras 6] [--runs 3] [--compare]

Audits LOG once, then builds a result with `--cameras` cameras (the log's cameras,
repeated under new names when it has fewer: the same real frame tables), renders the
report and loads it in headless Chromium (`--dump-dom`: parse, scripts run at load,
layout), minus the same on an empty page (browser start-up); median of `--runs`.
With --compare, the same series (after the report's decimation) are drawn by Plotly
(its wheel's plotly.min.js inlined) and Vega-Lite (altair, vl-convert's inlined bundle),
when those packages are installed (they are not syncaudit dependencies).
"""

from __future__ import annotations

import argparse
import copy
import re
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from browser import CHROMIUM, CHROMIUM_FLAGS
from syncaudit.audit.run import AuditResult, audit_log
from syncaudit.report.html import (
    camera_plots,
    latency_plots,
    render_audit_html,
    time_origin_ns,
)
from syncaudit.report.plot import _series_points
from syncaudit.rig import load_rig

SCRIPT_MS: dict[str, list[float]] = {}
"""Per page, the report script's own run time (data-script-ms) in each load."""


def _chromium_s(page: Path) -> float:
    """Wall time of loading a page to its DOM after the load event (browser start included)."""
    assert CHROMIUM is not None
    with tempfile.TemporaryDirectory() as profile:
        start = time.perf_counter()
        done = subprocess.run(
            [CHROMIUM, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", "--dump-dom", page.as_uri()],
            capture_output=True,
            text=True,
            timeout=300,
            check=True,
        )
        seconds = time.perf_counter() - start
    found = re.search(r'data-script-ms="([\d.]+)"', done.stdout)
    if found:
        SCRIPT_MS.setdefault(page.name, []).append(float(found.group(1)))
    return seconds


def _median_s(page: Path, runs: int) -> float:
    return statistics.median(_chromium_s(page) for _ in range(runs))


def _widen(result: AuditResult, cameras: int) -> AuditResult:
    """The result with `cameras` cameras: the log's own, then copies under new names."""
    wide = copy.copy(result)
    wide.cameras = []
    for i in range(cameras):
        cam = copy.copy(result.cameras[i % len(result.cameras)])
        cam.sync = copy.copy(cam.sync)
        cam.sync.camera = f"{cam.sync.camera}_{i}" if i >= len(result.cameras) else cam.sync.camera
        wide.cameras.append(cam)
    return wide


def _series(result: AuditResult) -> list[tuple[str, list[tuple[str, Any, Any]]]]:
    """Per plot: (title, [(label, x, y)]) after the report's decimation."""
    origin = time_origin_ns(result)
    out = []
    for cam in result.cameras:
        for plot in camera_plots(cam, result, origin) + latency_plots(cam, origin):
            lines = [(s.label, *_series_points(s)[:2]) for s in plot.series]
            out.append((f"{cam.sync.camera}: {plot.title}", lines))
    return out


def _plotly_page(plots: list[tuple[str, list[tuple[str, Any, Any]]]], path: Path) -> bool:
    """One Plotly figure per plot (its own div), plotly.min.js inlined once."""
    try:
        import plotly
        import plotly.graph_objects as go
        from plotly.offline import get_plotlyjs
    except ImportError:
        return False
    divs = []
    for title, lines in plots:
        fig = go.Figure(
            [go.Scatter(x=x, y=y, name=label, mode="lines") for label, x, y in lines],
            layout={"title": title, "height": 230, "width": 1000},
        )
        divs.append(plotly.io.to_html(fig, include_plotlyjs=False, full_html=False))
    path.write_text(
        "<!doctype html><html><head><meta charset=utf-8>"
        f"<script>{get_plotlyjs()}</script></head><body>{''.join(divs)}</body></html>"
    )
    return True


def _vega_page(plots: list[tuple[str, list[tuple[str, Any, Any]]]], path: Path) -> bool:
    try:
        import altair as alt
        import pandas as pd
    except ImportError:
        return False
    alt.data_transformers.disable_max_rows()
    charts = []
    for title, lines in plots:
        frame = pd.concat(
            [pd.DataFrame({"t_s": x, "value": y, "series": label}) for label, x, y in lines]
        )
        charts.append(
            alt.Chart(frame, title=title, width=900, height=170)
            .mark_line()
            .encode(x="t_s:Q", y="value:Q", color="series:N")
            .interactive(bind_y=False)
        )
    alt.vconcat(*charts).save(str(path), inline=True)
    return True


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log")
    parser.add_argument("--rig")
    parser.add_argument("--cameras", type=int, default=6)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--compare", action="store_true")
    args = parser.parse_args()
    warnings.filterwarnings("ignore", category=UserWarning)  # altair's selection notes
    rig = load_rig(Path(args.rig)) if args.rig else None
    result = _widen(audit_log(args.log, rig), args.cameras)
    frames = [len(c.sync.frames) for c in result.cameras]
    print(f"{len(frames)} cameras x {frames[0]} frames, {result.lidar.revolutions} revolutions")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        blank = folder / "blank.html"
        blank.write_text("<!doctype html><title>blank</title>")
        base = _median_s(blank, args.runs)
        pages = {}
        start = time.perf_counter()
        report = folder / "report.html"
        report.write_text(render_audit_html(result))
        print(f"hand SVG: rendered in Python in {time.perf_counter() - start:.2f} s")
        pages["hand SVG (syncaudit)"] = report
        if args.compare:
            plots = _series(result)
            if _plotly_page(plots, folder / "plotly.html"):
                pages["Plotly (inlined plotly.min.js)"] = folder / "plotly.html"
            if _vega_page(plots, folder / "vega.html"):
                pages["Vega-Lite (altair, inlined)"] = folder / "vega.html"
        print(f"browser start-up (blank page, median of {args.runs}): {base:.2f} s")
        print("| page | size (MB) | load to DOM, less start-up (s) |")
        print("| --- | --- | --- |")
        for name, page in pages.items():
            seconds = _median_s(page, args.runs) - base
            print(f"| {name} | {page.stat().st_size / 1e6:.2f} | {seconds:.2f} |")
        for name, values in SCRIPT_MS.items():
            print(f"{name}: the report script ran {statistics.median(values):.0f} ms (median)")


if __name__ == "__main__":
    main()
