"""The calibration's figures: each LiDAR's map from above by stop, mounts on it, free directions."""

from __future__ import annotations

import math
import re
from collections.abc import Callable

import numpy as np
import pytest

from syncaudit.calib import se3
from syncaudit.calib.result import CalibrationResult, DegeneracyOut, StopPointsOut, TopViewOut
from syncaudit.report.calib_figures import calibration_figures
from syncaudit.report.report_page import render_report_html
from syncaudit.report.topview import MAX_MAP_POINTS, stop_colour, thin_stops, top_view_svg

Load = Callable[[str], CalibrationResult]
TopViews = Callable[..., CalibrationResult]


def _figure(html: str, kind: str) -> list[str]:
    return re.findall(rf'<figure class="xy" data-kind="{kind}".*?</figure>', html, re.S)


def _attrs(tag: str) -> dict[str, str]:
    return dict(re.findall(r'([\w-]+)="([^"]*)"', tag))


def _points(path_d: str) -> np.ndarray:
    """(x, y) metres from a map path ('Mu,vh0' with u = -y, v = -x)."""
    uv = np.array(re.findall(r"M(-?[\d.]+),(-?[\d.]+)h0", path_d), dtype=float)
    return np.stack([-uv[:, 1], -uv[:, 0]], axis=1)


def _map_geometry(figure: str) -> tuple[dict[str, str], list[float]]:
    """The points <svg>'s attributes and its viewBox."""
    tag = re.search(r'<svg class="points"[^>]*>', figure)
    assert tag is not None
    attrs = _attrs(tag.group(0))
    return attrs, [float(v) for v in attrs["viewBox"].split()]


def test_one_map_per_lidar_coloured_by_stop(calibration: Load, top_views: TopViews) -> None:
    result = top_views(calibration("calib_turntable_32"))
    html = calibration_figures(result)
    maps = _figure(html, "top-view")
    assert [_attrs(m[: m.index(">")])["data-lidar"] for m in maps] == [
        lidar.frame_id for lidar in result.lidars
    ]
    for figure, lidar in zip(maps, result.lidars, strict=True):
        assert lidar.top_view is not None
        paths = re.findall(r'<path class="stop"[^>]*/>', figure)
        assert len(paths) == len(lidar.top_view.stops) == 12
        colours = [_attrs(p)["stroke"] for p in paths]
        assert colours == [stop_colour(i) for i in range(12)] and len(set(colours)) == 12
        for path, stop in zip(paths, lidar.top_view.stops, strict=True):
            a = _attrs(path)
            assert int(a["data-stop"]) == stop.stop and int(a["data-n"]) == len(stop.x_m)
            # Every point where the stop put it, to the centimetre written.
            drawn = _points(a["d"])
            np.testing.assert_allclose(drawn[:, 0], stop.x_m, atol=0.0051)
            np.testing.assert_allclose(drawn[:, 1], stop.y_m, atol=0.0051)
        legend = re.findall(
            r'<li data-stop="(\d+)"><span class="swatch" style="background:([^"]+)"', figure
        )
        assert legend == [(str(s.stop), stop_colour(i)) for i, s in enumerate(lidar.top_view.stops)]


def test_map_axes_have_equal_scales_and_metre_ticks(calibration: Load, top_views: TopViews) -> None:
    result = top_views(calibration("calib_turntable_32"))
    figure = _figure(calibration_figures(result), "top-view")[0]
    attrs, (u0, v0, du, dv) = _map_geometry(figure)
    px_per_m_across = float(attrs["width"]) / du
    px_per_m_up = float(attrs["height"]) / dv
    assert px_per_m_across == pytest.approx(px_per_m_up, rel=0.005)
    # The hall (x -8..12 m, y -7..7 m) and 4 % of its 20 m margin: x up, y to the left.
    assert (-v0, dv) == pytest.approx((12.8, 21.6), abs=1e-3)
    assert (-u0, du) == pytest.approx((7.8, 15.6), abs=1e-3)
    # Ticks: round metres, one step on both axes, spaced by the same pixels per metre.
    y_ticks = re.findall(r'<text x="([\d.]+)" y="[\d.]+" class="xtick">([^<]+)<', figure)
    x_ticks = re.findall(r'<text x="[\d.]+" y="([\d.]+)" class="yt">([^<]+)<', figure)
    assert len(y_ticks) >= 3 and len(x_ticks) >= 3
    for ticks, sign in ((y_ticks, -1), (x_ticks, -1)):
        pos = np.array([float(p) for p, _ in ticks])
        value = np.array([float(t.replace(",", "")) for _, t in ticks])
        assert np.all(value == np.round(value))  # whole metres at this size
        slope = np.diff(pos) / np.diff(value)
        np.testing.assert_allclose(slope, sign * px_per_m_up, rtol=0.01)
    steps = {np.diff([float(t) for _, t in ticks])[0] for ticks in (y_ticks, x_ticks)}
    assert len(steps) == 1
    assert "x, forward [m]" in figure and "y, left [m]" in figure


def test_mounts_recorded_and_estimated_on_each_map(calibration: Load, top_views: TopViews) -> None:
    result = top_views(calibration("calib_turntable_32"))
    html = calibration_figures(result)
    ext = result.extrinsics[0]
    assert ext.result is not None
    recorded, estimated = np.asarray(ext.recorded.matrix), np.asarray(ext.result.matrix)
    expected = {
        # the reference LiDAR's map: its own frame
        result.reference_frame_id: {
            ("lidar_front", "reference"): np.eye(4),
            ("lidar_rear", "recorded"): recorded,
            ("lidar_rear", "estimated"): estimated,
        },
        # the rear LiDAR's map: its frame as recorded, so its recorded mount is the origin
        "lidar_rear": {
            ("lidar_front", "reference"): np.linalg.inv(recorded),
            ("lidar_rear", "recorded"): np.eye(4),
            ("lidar_rear", "estimated"): np.linalg.inv(recorded) @ estimated,
        },
    }
    # The mounts figure (no points) holds them as the reference LiDAR's map does.
    (mounts,) = _figure(html, "mounts")
    as_map = mounts.replace('data-kind="mounts"', 'data-lidar="lidar_front"', 1)
    for figure in [as_map, *_figure(html, "top-view")]:
        lidar = _attrs(figure[: figure.index(">")])["data-lidar"]
        marks = {
            (a["data-name"], a["data-mount"]): (float(a["data-x-m"]), float(a["data-y-m"]))
            for a in map(_attrs, re.findall(r'<g class="mount"[^>]*>', figure))
        }
        assert set(marks) == set(expected[lidar])
        for key, pose in expected[lidar].items():
            assert marks[key] == pytest.approx((pose[0, 3], pose[1, 3]), abs=1e-4), key
    # The estimate sits 0.3 cm from the recorded mount here: both drawn, told apart by shape.
    assert 'data-mount="estimated"' in html and "estimated mount</li>" in html


def test_maps_in_the_base_frame_place_the_mounts_by_the_reference_mount(
    calibration: Load, top_views: TopViews
) -> None:
    base_from_reference = se3.make_transform(se3.rot_z(math.radians(2.0)), (1.2, -0.1, 1.9))
    result = top_views(calibration("calib_turntable_32"), base_from_reference=base_from_reference)
    ext = result.extrinsics[0]
    assert ext.result is not None and result.reference_mount is not None
    expected = {
        ("lidar_front", "reference"): base_from_reference,
        ("lidar_rear", "recorded"): base_from_reference @ np.asarray(ext.recorded.matrix),
        ("lidar_rear", "estimated"): base_from_reference @ np.asarray(ext.result.matrix),
    }
    figures = _figure(calibration_figures(result), "top-view")
    assert len(figures) == 2
    for figure in figures:
        assert "in base_link at stop 0, lidar_" in figure
        marks = {
            (a["data-name"], a["data-mount"]): (float(a["data-x-m"]), float(a["data-y-m"]))
            for a in map(_attrs, re.findall(r'<g class="mount"[^>]*>', figure))
        }
        assert set(marks) == set(expected)
        for key, pose in expected.items():
            assert marks[key] == pytest.approx((pose[0, 3], pose[1, 3]), abs=1e-4), key
    # Without the reference LiDAR's mount the base frame cannot hold the mounts: said so.
    unplaced = result.model_copy(update={"reference_mount": None})
    for figure in _figure(calibration_figures(unplaced), "top-view"):
        assert '<g class="mount"' not in figure and "mounts not drawn" in figure


def test_a_dense_map_is_thinned_under_the_budget_keeping_its_extent(
    calibration: Load, top_views: TopViews
) -> None:
    result = top_views(calibration("calib_turntable_32"), spacing_m=0.005)
    view = result.lidars[0].top_view
    assert view is not None
    held = sum(len(s.x_m) for s in view.stops)
    assert held > 4 * MAX_MAP_POINTS
    stops, cell = thin_stops(view)
    assert sum(p.x_m.size for p in stops) <= MAX_MAP_POINTS and cell > view.cell_m
    for drawn, stop in zip(stops, view.stops, strict=True):
        assert drawn.x_m.size > 0 and drawn.recorded == len(stop.x_m)
        # Thinning keeps one point per occupied cell: the stop's extent shrinks by < a cell.
        assert drawn.x_m.min() - min(stop.x_m) < cell and max(stop.x_m) - drawn.x_m.max() < cell
        assert drawn.y_m.min() - min(stop.y_m) < cell and max(stop.y_m) - drawn.y_m.max() < cell
    figure = top_view_svg(result, "lidar_front", view)
    assert int(_attrs(figure[: figure.index(">")])["data-n"]) <= MAX_MAP_POINTS
    assert f"of {held:,} points" in figure
    assert len(figure) < 400_000  # bytes of the map in the page


def test_more_stops_than_palette_colours_stay_distinct() -> None:
    colours = [stop_colour(i) for i in range(40)]
    assert len(set(colours)) == 40 and all(re.fullmatch(r"#[0-9a-f]{6}", c) for c in colours)


def test_map_text_is_escaped(calibration: Load, top_views: TopViews, hostile: str) -> None:
    base = top_views(calibration("calib_turntable_32"))
    lidar = base.lidars[0]
    assert lidar.top_view is not None
    view = lidar.top_view.model_copy(update={"frame": f"odom{hostile} at stop 0"})
    marked = lidar.model_copy(update={"top_view": view, "frame_id": f"front{hostile}"})
    html = calibration_figures(base.model_copy(update={"lidars": [marked, *base.lidars[1:]]}))
    assert hostile not in html and "<script>" not in html
    assert "in odom&lt;script&gt;" in html and 'data-lidar="front&lt;script&gt;' in html


def test_no_top_view_no_map(calibration: Load) -> None:
    result = calibration("calib_turntable_32")
    assert all(lidar.top_view is None for lidar in result.lidars)
    assert _figure(calibration_figures(result), "top-view") == []
    empty = result.lidars[0].model_copy(
        update={"top_view": TopViewOut(frame="lidar_front at stop 0", cell_m=0.1, stops=[])}
    )
    assert (
        _figure(calibration_figures(result.model_copy(update={"lidars": [empty]})), "top-view")
        == []
    )
    one = TopViewOut(
        frame="lidar_front at stop 0",
        cell_m=0.1,
        stops=[StopPointsOut(stop=0, x_m=[1.0, math.nan], y_m=[2.0, 0.0])],
    )
    figure = top_view_svg(result, "lidar_front", one)
    assert 'data-n="1"' in figure  # the NaN point is dropped, not drawn at 0


@pytest.mark.parametrize(
    ("direction", "kind"),
    [
        ((-0.70, 0.71, 0.0), "translation"),
        ((0.0, 0.02, 1.0), "rotation"),
        ((0.1, 0.0, 0.99), "translation"),
    ],
)
def test_scene_degeneracy_is_drawn_from_the_structured_field(
    calibration: Load, direction: tuple[float, float, float], kind: str
) -> None:
    refused = calibration("calib_ground_and_wall")
    # Before: nothing structured, and the reasons' text is no longer parsed.
    assert "degenerate view (translation along" in (refused.reason or "")
    assert _figure(calibration_figures(refused), "scene-degeneracy") == []
    assert _figure(calibration_figures(refused), "degenerate") == []
    free = DegeneracyOut(
        kind=kind, direction=direction, frame="base_link", information=0.002, limit=0.01
    )
    html = render_report_html(None, refused.model_copy(update={"degeneracy": free}))
    (figure,) = _figure(html, "scene-degeneracy")
    a = _attrs(figure[: figure.index(">")])
    assert a["data-free"] == kind
    assert [float(v) for v in a["data-direction"].split()] == pytest.approx(direction)
    assert "in base_link" in figure and "information 0.002 vs limit 0.01" in figure
    # The bar: information over twice the limit's width, the limit line in its middle.
    bar = _attrs(re.search(r'<rect class="information"[^>]*>', figure).group(0))  # type: ignore[union-attr]
    assert float(bar["width"]) == pytest.approx(200 * 0.2 / 2)
    if kind == "rotation":
        assert 'class="free-rotation"' in figure
    elif math.hypot(direction[0], direction[1]) < 0.3:
        assert 'class="free-translation" cx=' in figure  # a ring: mostly vertical
    else:
        lines = re.findall(
            r'<g class="free-translation"><line x1="([\d.-]+)" y1="([\d.-]+)" '
            r'x2="([\d.-]+)" y2="([\d.-]+)"',
            figure,
        )
        assert len(lines) == 2
        for x1, y1, x2, y2 in lines:
            dx_screen, dy_screen = float(x2) - float(x1), float(y2) - float(y1)
            # Screen right is -y and down is -x: the arrows lie along +-direction.
            cross = dx_screen * -direction[0] - dy_screen * -direction[1]
            assert abs(cross) < 1.0
        ends = {(round(float(x2)), round(float(y2))) for _, _, x2, y2 in lines}
        assert len(ends) == 2  # both ways


def test_degeneracy_drawn_on_the_map_in_its_frame(calibration: Load, top_views: TopViews) -> None:
    frames = {
        "lidar_front": "base_link at stop 0, lidar_front placed by the recorded extrinsic",
        "lidar_rear": "base_link at stop 5, lidar_rear placed by the recorded extrinsic",
    }
    result = top_views(calibration("calib_turntable_32"), frames=frames)
    free = DegeneracyOut(
        kind="translation",
        direction=(1.0, 0.0, 0.0),
        frame="base_link at stop 0",
        information=0.0,
        limit=0.01,
    )
    maps = _figure(calibration_figures(result.model_copy(update={"degeneracy": free})), "top-view")
    # Only the map in the same frame (the base at the same stop) carries the arrow.
    assert ["free-translation" in m for m in maps] == [True, False]


def test_refused_alignments_drawn_from_their_conditioning(calibration: Load) -> None:
    ok = calibration("calib_turntable_32")
    refused = [
        p for lidar in ok.lidars for p in lidar.pairs if "degenerate" in (p.alignment.reason or "")
    ]
    (pair,) = refused
    (figure,) = _figure(calibration_figures(ok), "degenerate")
    c = pair.alignment.conditioning
    tx, ty, tz = c.weakest_translation
    assert (
        f"translation ({tx:+.2f}, {ty:+.2f}, {tz:+.2f}) info {c.translation_information:.2g}"
        in figure
    )
    # The reason's own numbers are not what is drawn: change them and the figure follows
    # the structured field only.
    moved = pair.alignment.model_copy(
        update={
            "conditioning": c.model_copy(
                update={"weakest_translation": (0.0, 1.0, 0.0), "translation_information": 0.0042}
            )
        }
    )
    lidars = [
        lidar.model_copy(
            update={
                "pairs": [
                    p.model_copy(update={"alignment": moved}) if p is pair else p
                    for p in lidar.pairs
                ]
            }
        )
        for lidar in ok.lidars
    ]
    (figure,) = _figure(calibration_figures(ok.model_copy(update={"lidars": lidars})), "degenerate")
    assert "translation (+0.00, +1.00, +0.00) info 0.0042" in figure
