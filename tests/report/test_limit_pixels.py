"""Issue 23 finding 7: limit lines and refused pairs as the browser paints them.

The Eq. 5 / Eq. 6 limit lines are visible in the rendered pixels.

They were drawn in the rolling plots' stretched data coordinates (µs over seconds), so the
1.2 px stroke became ~0.04 px: in the DOM, invisible on screen. Here Chromium renders the
report, and the screenshot's pixels along the line must be the limit's red over at least
40 % of the plot's width (the dash pattern 5 3 covers 62 %; series may cross it), whole
and zoomed to a time window.
"""

from __future__ import annotations

import base64
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from browser import ARTIFACTS, Session, needs_chromium
from pixels import png_rgb
from syncaudit.audit.run import AuditResult
from syncaudit.calib.result import CalibrationResult
from syncaudit.report.html import render_audit_html
from syncaudit.report.report_page import render_report_html

pytestmark = needs_chromium

_WHERE = """(() => {
  const figure = document.querySelectorAll('figure[data-kind="%s"]')[%d];
  figure.scrollIntoView();
  const line = figure.querySelector('line.limit');
  const area = figure.querySelector('svg.area');
  const m = line.getScreenCTM();
  const y = m.d * line.y1.baseVal.value + m.f;
  const left = figure.querySelector('svg.plot').getBoundingClientRect().left + area.x.baseVal.value;
  return [left, left + area.width.baseVal.value, y, window.scrollY];
})()"""


def _limit_red(image: np.ndarray) -> np.ndarray:
    """Pixels of the limit's red (#b00020, also anti-aliased over white): red well above
    green, blue not below green (the orange series has no blue)."""
    rgb = image.astype(int)
    return (rgb[:, :, 0] > rgb[:, :, 1] + 50) & (rgb[:, :, 2] >= rgb[:, :, 1] - 10)


def _covered(session: Session, kind: str, index: int, name: str) -> float:
    """Fraction of the plot's columns with the limit's red within 2 px of the line."""
    left, right, y, scroll = session.evaluate(_WHERE % (kind, index))
    clip = {"x": left, "y": y - 6 + scroll, "width": right - left, "height": 12, "scale": 1}
    data = session.call("Page.captureScreenshot", {"format": "png", "clip": clip})["data"]
    shot = ARTIFACTS / "report" / f"limit-{name}.png"
    shot.parent.mkdir(parents=True, exist_ok=True)
    shot.write_bytes(base64.b64decode(data))
    red = _limit_red(png_rgb(shot))
    return float(red[4:9].any(axis=0).mean())


@pytest.mark.parametrize("fragment", ["", "t=2-4.5"])
def test_limit_lines_are_drawn_in_pixels(audit: AuditResult, tmp_path: Path, fragment: str) -> None:
    page = tmp_path / "audit.html"
    page.write_text(render_audit_html(audit))
    with Session(height=900) as session:
        session.open(page, fragment=fragment)
        for kind in ("rolling-mean", "rolling-var"):
            for index in range(len(audit.cameras)):
                name = f"{kind}-{index}-{fragment or 'whole'}"
                assert _covered(session, kind, index, name) > 0.4, name
        assert session.console == [], session.console


def test_refused_calibration_pairs_are_painted_red_as_the_caption_says(
    calibration: Callable[[str], CalibrationResult], audit: AuditResult, tmp_path: Path
) -> None:
    """Finding 7: a stylesheet rule painted every bar blue over the bars' own fill."""
    result = calibration("calib_turntable_32")
    expected = [
        [
            "rgb(31, 95, 191)" if p.alignment.accepted else "rgb(176, 40, 58)"
            for p in lidar.pairs
            if p.alignment.after.rmse_cm is not None
        ]
        for lidar in result.lidars
        if lidar.pairs
    ]
    assert any("rgb(176, 40, 58)" in fills for fills in expected)
    page = tmp_path / "calib.html"
    page.write_text(render_report_html(audit, result))
    with Session(height=900) as session:
        session.open(page)
        painted = session.evaluate(
            """[...document.querySelectorAll('figure[data-kind="pair-residuals"]')].map(f =>
                 [...f.querySelectorAll('rect.bar')].map(r => getComputedStyle(r).fill))"""
        )
        histogram = session.evaluate(
            """[...new Set([...document.querySelectorAll('figure[data-kind="histogram"] rect.bar')]
                 .map(r => getComputedStyle(r).fill))]"""
        )
    # Bars are drawn in the chart's order; compare the colours as multisets per LiDAR.
    assert [sorted(p) for p in painted] == [sorted(e) for e in expected]
    assert histogram == ["rgb(31, 95, 191)"]  # the audit's histograms keep the default fill
