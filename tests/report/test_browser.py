"""The reports as a user sees them: loaded in a real headless Chromium (Debian's package)."""

from __future__ import annotations

import re
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest

from browser import Session, needs_chromium, render, screenshot
from syncaudit.audit.run import AuditResult
from syncaudit.calib.result import CalibrationResult, DegeneracyOut
from syncaudit.report.html import (
    frame_time_ns,
    render_audit_html,
    time_origin_ns,
)
from syncaudit.report.report_page import render_report_html

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
        len(time_plots) == 4 + 3 * 9
    )  # LiDAR 4; per camera error, Eq. 5, Eq. 6, t1..t4, t5, delay
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


def test_combined_report_with_maps_and_a_refused_calibration(
    audit: AuditResult,
    calibration: Callable[[str], CalibrationResult],
    top_views: Callable[..., CalibrationResult],
    tmp_path: Path,
) -> None:
    mapped = top_views(calibration("calib_turntable_32"), sector_deg=28.0)  # stops apart
    page = tmp_path / "combined.html"
    page.write_text(render_report_html(audit, mapped))
    with Session(height=1000) as browser:
        browser.open(page)
        assert browser.console == [], browser.console
        assert browser.evaluate("document.body.dataset.ready") == "yes"
        maps = browser.evaluate(
            """Array.from(document.querySelectorAll('figure[data-kind="top-view"]')).map(f => {
              const m = f.querySelector('svg.points').getScreenCTM();
              return {lidar: f.dataset.lidar, across: m.a, up: m.d,
                      paths: Array.from(f.querySelectorAll('path.stop')).map(
                        p => [p.dataset.stop, p.getAttribute('stroke'), p.getTotalLength()]),
                      legend: f.querySelectorAll('li[data-stop]').length};
            })"""
        )
        assert [m["lidar"] for m in maps] == ["lidar_front", "lidar_rear"]
        for drawn in maps:
            # Equal scales as the browser laid them out: pixels per metre across = up.
            assert drawn["across"] == pytest.approx(drawn["up"], rel=0.005)
            assert len(drawn["paths"]) == drawn["legend"] == 12
            assert len({colour for _, colour, _ in drawn["paths"]}) == 12
        # Hover a point only one stop holds: the read-out names that stop and the point.
        view = mapped.lidars[0].top_view
        assert view is not None
        seen: dict[tuple[float, float], list[int]] = {}
        for stop in view.stops:
            for xy in zip(stop.x_m, stop.y_m, strict=True):
                seen.setdefault((round(xy[0], 2), round(xy[1], 2)), []).append(stop.stop)
        (x_m, y_m), (only,) = next((xy, s) for xy, s in seen.items() if len(s) == 1)
        at = browser.evaluate(
            f"""(() => {{
              const f = document.querySelector('figure[data-kind="top-view"]');
              f.scrollIntoView({{block: 'center'}});
              const m = f.querySelector('svg.points').getScreenCTM();
              const p = new DOMPoint({-y_m}, {-x_m}).matrixTransform(m);
              return [p.x, p.y, Number(f.dataset.renderedPoints), Number(f.dataset.n)];
            }})()"""
        )
        assert at[2] == at[3] == sum(len(stop.x_m) for stop in view.stops)
        browser.mouse("mouseMoved", at[0], at[1])
        tip = _tip(browser)
        assert tip is not None
        cursor, nearest = tip.split("\n")
        assert nearest == f"stop {only}: x {x_m:.2f} m, y {y_m:.2f} m"
        read = re.fullmatch(r"x (-?[\d.]+) m, y (-?[\d.]+) m", cursor)
        assert read is not None, cursor
        # The cursor's own position, to a pixel (CDP rounds mouse coordinates).
        assert float(read.group(1)) == pytest.approx(x_m, abs=0.1)
        assert float(read.group(2)) == pytest.approx(y_m, abs=0.1)
        shot = browser.screenshot("report/calibration-map.png")
    assert shot.stat().st_size > 20_000

    refused = calibration("calib_ground_and_wall").model_copy(
        update={
            "degeneracy": DegeneracyOut(
                kind="translation",
                direction=(-0.70, 0.71, 0.0),
                frame="base_link",
                information=0.002,
                limit=0.01,
            )
        }
    )
    page.write_text(render_report_html(audit, refused))
    shown = render(page)
    assert shown.console == [], shown.console
    kinds = [f.get("data-kind") for f in _figures(shown.dom)]
    assert kinds.count("scene-degeneracy") == 1 and kinds.count("mounts") == 1
    assert kinds.count("error") == 3


def _plot_box(browser: Session, kind: str, index: int = 0) -> dict[str, float]:
    """Scroll a time plot into view; its hit area on screen and its time window."""
    box: dict[str, float] = browser.evaluate(
        f"""(() => {{
          const f = document.querySelectorAll('figure.tplot[data-kind="{kind}"]')[{index}];
          f.scrollIntoView({{block: 'center'}});
          const r = f.querySelector('rect.hit').getBoundingClientRect();
          const vb = f.querySelector('svg.area').viewBox.baseVal;
          return {{left: r.left, top: r.top, width: r.width, height: r.height,
                   t0: vb.x, span: vb.width}};
        }})()"""
    )
    return box


def _screen_x(box: dict[str, float], t_s: float) -> float:
    return box["left"] + (t_s - box["t0"]) / box["span"] * box["width"]


def _time_windows(browser: Session) -> list[list[float]]:
    windows: list[list[float]] = browser.evaluate(
        "Array.from(document.querySelectorAll('svg.area')).map("
        "a => [a.viewBox.baseVal.x, a.viewBox.baseVal.width])"
    )
    return windows


def _tip(browser: Session) -> str | None:
    tip: str | None = browser.evaluate(
        "(() => { const t = document.querySelector('div.tip'); return t.hidden ? null : t.textContent; })()"
    )
    return tip


def test_hover_shows_the_value_and_wall_clock_of_a_known_frame(
    audit: AuditResult, tmp_path: Path
) -> None:
    page = tmp_path / "audit.html"
    page.write_text(render_audit_html(audit))
    cam = audit.cameras[0]
    frames = cam.sync.frames
    origin_ns = time_origin_ns(audit)
    times_s = (frame_time_ns(cam) - origin_ns) / 1e9
    paired = np.flatnonzero(frames["paired"].to_numpy(dtype=bool))
    row = int(paired[len(paired) // 2])  # a paired frame mid-log
    t_s = float(times_s[row])
    error_us = float(frames["error_signed_ns"].iloc[row]) / 1e3
    with Session() as browser:
        browser.open(page)
        box = _plot_box(browser, "error")
        assert _tip(browser) is None
        browser.mouse("mouseMoved", _screen_x(box, t_s), box["top"] + box["height"] / 2)
        tip = _tip(browser)
        assert browser.console == [], browser.console
    assert tip is not None
    first, *series = tip.split("\n")
    head = re.fullmatch(r"t = ([\d.]+) s  \((\S+)Z\)", first)
    assert head is not None, first
    cursor_s = float(head.group(1))
    pixel_s = box["span"] / box["width"]
    assert abs(cursor_s - t_s) <= pixel_s
    # The wall clock is the log's start plus the cursor's time (UTC, to the millisecond).
    wall = datetime.fromisoformat(head.group(2)).replace(tzinfo=UTC)
    expected = datetime.fromtimestamp((origin_ns + cursor_s * 1e9) / 1e9, tz=UTC)
    assert abs((wall - expected).total_seconds()) <= 0.0015
    recorded = next(line for line in series if line.startswith("recorded: "))
    value = re.fullmatch(r"recorded: (-?[\d,.]+) µs  @ ([\d.]+) s", recorded)
    assert value is not None, recorded
    assert float(value.group(1).replace(",", "")) == pytest.approx(error_us, abs=0.051)
    assert float(value.group(2)) == pytest.approx(t_s, abs=0.0011)
    assert any(line.startswith("with self-adaptive correction (replayed): ") for line in series)


def test_drag_zooms_every_time_plot_and_double_click_resets(
    audit: AuditResult, tmp_path: Path
) -> None:
    page = tmp_path / "audit.html"
    page.write_text(render_audit_html(audit))
    with Session() as browser:
        browser.open(page)
        home = _time_windows(browser)
        box = _plot_box(browser, "error")
        pixel_s = box["span"] / box["width"]
        y = box["top"] + box["height"] / 2
        browser.drag((_screen_x(box, 3.0), y), (_screen_x(box, 5.5), y))
        zoomed = _time_windows(browser)
        assert len(zoomed) == 4 + 3 * 9
        for start, width in zoomed:
            assert start == pytest.approx(3.0, abs=pixel_s)
            assert start + width == pytest.approx(5.5, abs=pixel_s)
        link = browser.evaluate("location.hash")
        linked = re.fullmatch(r"#t=([\d.]+)-([\d.]+)", link)
        assert linked is not None, link
        assert float(linked.group(1)) == pytest.approx(3.0, abs=pixel_s)
        assert float(linked.group(2)) == pytest.approx(5.5, abs=pixel_s)
        ticks = browser.evaluate(
            "Array.from(document.querySelector('figure[data-kind=\"lidar-rpm\"] g.xt')"
            ".querySelectorAll('text')).map(t => Number(t.textContent))"
        )
        assert len(ticks) >= 5 and 3.0 - pixel_s <= ticks[0] and ticks[-1] <= 5.5 + pixel_s
        # A second drag, backwards, on another camera's t4 plot zooms all again, further.
        box = _plot_box(browser, "latency-t4", 2)
        y = box["top"] + box["height"] / 2
        browser.drag((_screen_x(box, 4.6), y), (_screen_x(box, 4.0), y))
        pixel_s = box["span"] / box["width"]
        for start, width in _time_windows(browser):
            assert start == pytest.approx(4.0, abs=pixel_s)
            assert start + width == pytest.approx(4.6, abs=pixel_s)
        # Hover after zooming reads the zoomed axis: the plot's middle is 4.3 s.
        browser.mouse("mouseMoved", box["left"] + box["width"] / 2, y)
        tip = _tip(browser)
        assert tip is not None
        middle = re.match(r"t = ([\d.]+) s", tip)
        assert middle is not None and float(middle.group(1)) == pytest.approx(4.3, abs=2 * pixel_s)
        browser.double_click(box["left"] + box["width"] / 2, y)
        for (start, width), (home_start, home_width) in zip(
            _time_windows(browser), home, strict=True
        ):
            assert (start, width) == pytest.approx((home_start, home_width), rel=1e-6)
        assert browser.evaluate("location.hash") == ""
        assert browser.console == [], browser.console
