"""The plot primitives: envelopes keep every extreme, steps lose nothing, ticks are round."""

from __future__ import annotations

import re

import numpy as np

from syncaudit.report.html import rolling_min
from syncaudit.report.plot import (
    MAX_POINTS,
    Series,
    TimePlot,
    envelope,
    nice_ticks,
    steps_only,
    tick_labels,
    time_plot_svg,
)


def test_envelope_keeps_each_buckets_extremes() -> None:
    rng = np.random.default_rng(0)
    x = np.arange(60_000, dtype=float) / 100.0  # ten minutes at 100 Hz
    y = rng.normal(0, 100, x.size)
    y[12_345] = 9_999.0  # one spike
    y[50_000] = -7_777.0
    y[7] = np.nan
    ex, ey = envelope(x, y)
    assert ex.size <= MAX_POINTS and np.all(np.diff(ex) > 0)
    assert 9_999.0 in ey and -7_777.0 in ey
    assert ey.max() == np.nanmax(y) and ey.min() == np.nanmin(y)
    bucket = np.linspace(0, x.size, MAX_POINTS // 2 + 1).astype(int)
    lo, hi = bucket[3], bucket[4]
    inside = (ex >= x[lo]) & (ex < x[hi])
    assert set(ey[inside]) == {np.nanmin(y[lo:hi]), np.nanmax(y[lo:hi])}
    small_x, _ = envelope(x[:100], y[:100])
    assert small_x.size == 99  # under the cap: every finite point


def test_steps_only_is_lossless() -> None:
    x = np.arange(10, dtype=float)
    y = np.array([1, 1, 1, 2, 2, 3, 3, 3, 3, 1], dtype=float)
    sx, sy = steps_only(x, y)
    assert list(sx) == [0, 2, 3, 4, 5, 8, 9]
    assert np.array_equal(np.interp(x, sx, sy), y)  # the held value at every frame


def test_nice_ticks() -> None:
    assert nice_ticks(0, 600, 10) == [0, 100, 200, 300, 400, 500, 600]
    assert nice_ticks(-5411, 5411, 6) == [-4000, -2000, 0, 2000, 4000]
    assert nice_ticks(0.1, 0.1) == [0.1]


def test_a_long_series_is_capped_per_series() -> None:
    x = np.arange(6_000, dtype=float) / 10
    plot = TimePlot("t", "µs", [Series("a", x, np.sin(x)), Series("b", x, np.cos(x))])
    svg = time_plot_svg(plot)
    counts = [int(n) for n in __import__("re").findall(r'data-n="(\d+)"', svg)]
    assert len(counts) == 2 and all(n <= MAX_POINTS for n in counts)


def test_a_line_breaks_across_missing_frames() -> None:
    x = np.r_[np.arange(10.0), np.arange(30.0, 40.0)] / 10  # 2 s of frames missing
    svg = time_plot_svg(TimePlot("t", "µs", [Series("a", x, np.ones_like(x))]))
    d = __import__("re").search(r' d="([^"]*)"', svg)
    assert d is not None and d.group(1).count("M") == 2


def test_tick_labels_carry_the_decimals_their_spacing_needs() -> None:
    assert tick_labels(nice_ticks(599.85, 600.2)) == ["599.9", "600.0", "600.1", "600.2"]
    assert tick_labels(nice_ticks(2.0, 2.06)) == ["2.00", "2.02", "2.04", "2.06"]
    assert tick_labels(nice_ticks(0, 600, 10)) == ["0", "100", "200", "300", "400", "500", "600"]
    assert tick_labels([-4000.0, -2000.0, 0.0, 2000.0]) == ["-4,000", "-2,000", "0", "2,000"]


def test_count_plots_start_at_zero_with_whole_ticks() -> None:
    x = np.arange(5, dtype=float)
    plot = TimePlot("drops", "packets", counts=True)
    plot.series.append(Series("dropped", x, np.array([1.0, 2.0, 1.0, 1.0, 2.0]), dots=True))
    svg = time_plot_svg(plot)
    ticks = re.findall(r'class="yt">([^<]+)<', svg)
    assert ticks[0] == "0" and all(t.isdigit() for t in ticks) and "2" in ticks


def test_rolling_minimum_of_the_clock() -> None:
    values = np.array([5.0, 3.0, 4.0, 9.0, 8.0, 7.0, 1.0])
    np.testing.assert_array_equal(rolling_min(values, 3), [5, 3, 3, 3, 4, 7, 1])
    np.testing.assert_array_equal(rolling_min(values, 1), values)
