"""The reports as a user sees them: loaded in a real headless Chromium (Debian's package)."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

from browser import needs_chromium, render, screenshot
from syncaudit.audit import AuditResult
from syncaudit.calib.result import CalibrationResult
from syncaudit.report.html import render_audit_html, render_report_html

pytestmark = needs_chromium


def _figures(dom: str) -> list[dict[str, str]]:
    """The attributes of every <figure> in the DOM the browser left."""
    out = []
    for tag in re.findall(r"<figure\b[^>]*>", dom):
        out.append(dict(re.findall(r'([\w-]+)="([^"]*)"', tag)))
    return out


def test_audit_report_renders_with_every_plot_and_point(audit: AuditResult, tmp_path: Path) -> None:
    page = tmp_path / "audit.html"
    page.write_text(render_audit_html(audit))
    shown = render(page, fragment="t=2-4.5")  # a link to a time window (one browser run)
    assert shown.console == [], shown.console
    assert 'data-ready="yes"' in shown.dom  # the inline script ran to its end
    figures = _figures(shown.dom)
    time_plots = [f for f in figures if f.get("class") == "tplot"]
    assert (
        len(time_plots) == 3 + 3 * 9
    )  # LiDAR 3; per camera error, Eq. 5, Eq. 6, t1..t4, t5, delay
    assert len([f for f in figures if f.get("data-kind") == "histogram"]) == 3
    # The script read every point of every series back from the drawn SVG.
    for figure, drawn in zip(
        time_plots, re.findall(r'<figure class="tplot".*?</figure>', shown.dom, re.S), strict=True
    ):
        expected = sum(int(n) for n in re.findall(r'data-n="(\d+)"', drawn))
        assert int(figure["data-rendered-points"]) == expected, figure["data-kind"]
    errors = [f for f in time_plots if f["data-kind"] == "error"]
    paired = [int(c.sync.frames["paired"].sum()) for c in audit.cameras]
    replayed = [c.replay.errors_ns.size if c.replay else 0 for c in audit.cameras]
    assert [int(f["data-rendered-points"]) for f in errors] == [
        p + r for p, r in zip(paired, replayed, strict=True)
    ]
    # The link zoomed every time plot to 2 s .. 4.5 s and redrew the time ticks.
    boxes = re.findall(r'<svg class="area"[^>]*viewBox="([^"]+)"', shown.dom)
    assert len(boxes) == len(time_plots)
    for box in boxes:
        x, _, width, _ = (float(v) for v in box.split())
        assert (x, width) == (2.0, 2.5)
    first = re.search(r'<g class="xt"[^>]*>(.*?)</g>', shown.dom, re.S)
    assert first is not None
    ticks = [float(t) for t in re.findall(r'class="xtick"[^>]*>([^<]+)<', first.group(1))]
    assert ticks[0] >= 2.0 and ticks[-1] <= 4.5 and len(ticks) >= 5
    assert re.search(r'<body[^>]*data-t0-ms="1700000000000.000"', shown.dom)  # wall clock
    shot = screenshot(page, "report/audit.png", height=2600)
    assert shot.stat().st_size > 20_000 and shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_text_from_the_log_shows_as_text(
    hostile_audit: AuditResult, hostile: str, tmp_path: Path
) -> None:
    page = tmp_path / "hostile.html"
    page.write_text(render_audit_html(hostile_audit))
    shown = render(page)
    assert shown.console == [], shown.console  # alert() would not log, but a parse error would
    assert shown.dom.count("<script") == 1  # only the page's own script is an element
    escaped = hostile.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    assert f"camera cam{escaped}" in shown.dom
    assert f"/lidar{escaped}" in shown.dom and f"frame id {escaped} unknown" in shown.dom
    assert 'data-ready="yes"' in shown.dom


def test_combined_report_with_a_refused_calibration(
    audit: AuditResult, calibration: Callable[[str], CalibrationResult], tmp_path: Path
) -> None:
    page = tmp_path / "combined.html"
    page.write_text(render_report_html(audit, calibration("calib_ground_and_wall")))
    shown = render(page)
    assert shown.console == [], shown.console
    kinds = [f.get("data-kind") for f in _figures(shown.dom)]
    assert kinds.count("degenerate") == 2 and kinds.count("mounts") == 1
    assert kinds.count("error") == 3
