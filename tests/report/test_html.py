"""The HTML report's content: every plot of the method, its data equal to the audit's, escaped."""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from syncaudit.audit.run import AuditResult
from syncaudit.calib.result import CalibrationResult, DegeneracyOut
from syncaudit.cli import app
from syncaudit.report.html import render_audit_html
from syncaudit.report.report_page import render_report_html

CAMERA_PLOTS = (
    "error",
    "rolling-mean",
    "rolling-var",
    "latency-t1",
    "latency-t2",
    "latency-t3",
    "latency-t4",
    "exposure",
    "delay",
)
LIDAR_PLOTS = ("lidar-rpm", "lidar-packets", "lidar-drops", "lidar-clock")
THREE_CAMERAS = Path(__file__).resolve().parents[2] / "sample_logs" / "vlp16_three_cameras.mcap"
Load = Callable[[str], CalibrationResult]


class _Page(HTMLParser):
    """Tags, text and the series (<path data-label>) of each figure."""

    def __init__(self) -> None:
        super().__init__()
        self.tags: list[str] = []
        self.text: list[str] = []
        self.figures: list[tuple[str, dict[str, str]]] = []
        self.paths: list[tuple[str, dict[str, str]]] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append(tag)
        a = {k: v or "" for k, v in attrs}
        for name in ("src", "href"):
            assert name not in a, f"external reference {a[name]}"
        if tag == "figure":
            self.figures.append((a.get("data-kind", ""), a))
        if tag == "path" and "data-label" in a:
            self.paths.append((self.figures[-1][0], a))

    def handle_data(self, data: str) -> None:
        self.text.append(data)


def _parse(page: str) -> _Page:
    parser = _Page()
    parser.feed(page)
    return parser


def _path_values(d: str) -> tuple[np.ndarray, np.ndarray]:
    nums = np.array([float(v) for v in re.findall(r"-?\d+(?:\.\d+)?", d)])
    return nums[0::2], -nums[1::2]


def test_every_plot_of_the_method_per_camera_and_lidar(audit: AuditResult) -> None:
    page = _parse(render_audit_html(audit))
    kinds = [k for k, _ in page.figures]
    for kind in CAMERA_PLOTS:
        assert kinds.count(kind) == 3, kind
    assert kinds.count("histogram") == 3
    for kind in LIDAR_PLOTS:
        assert kinds.count(kind) == 1, kind
    assert page.tags.count("script") == 1  # ours, inline
    text = " ".join(page.text)
    assert "FAIL" in text and "t_sleep recommended, Eq. 2" in text
    assert "Eq. 5 limit ±250 µs" in text and "time into the log [s]" in text


def test_plotted_values_are_the_audits(audit: AuditResult) -> None:
    """Recorded and replayed errors, delays and RPM drawn are the result's own numbers."""
    page = _parse(render_audit_html(audit))
    cam = audit.cameras[0]
    frames = cam.sync.frames
    errors = [a for kind, a in page.paths if kind == "error"][:2]
    assert [a["data-label"] for a in errors] == [
        "recorded",
        "with self-adaptive correction (replayed)",
    ]
    paired = frames["paired"].to_numpy(dtype=bool)
    recorded = frames["error_signed_ns"].to_numpy(dtype=float)[paired] / 1e3
    _, drawn = _path_values(errors[0]["d"])
    assert int(errors[0]["data-n"]) == paired.sum() == drawn.size  # under MAX_POINTS: all
    np.testing.assert_allclose(drawn, recorded, atol=0.051)
    assert cam.replay is not None
    _, corrected = _path_values(errors[1]["d"])
    np.testing.assert_allclose(corrected, cam.replay.errors_ns / 1e3, atol=0.051)
    # The replay's adjustments are dots at the delays it set.
    dots = next(a for kind, a in page.paths if kind == "delay" and "dots" in a.get("class", ""))
    nums = [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?", dots["d"])]
    np.testing.assert_allclose(
        -np.array(nums[1::4]), cam.replay.adjustment_delays_ns / 1e3, atol=0.051
    )
    assert int(dots["data-n"]) == cam.replay.adjustments
    # One RPM point per revolution with a measured rate.
    rpm = next(a for kind, a in page.paths if kind == "lidar-rpm")
    assert audit.revolutions is not None
    omega = audit.revolutions.omega_deg_s
    assert int(rpm["data-n"]) == np.isfinite(omega).sum()
    np.testing.assert_allclose(
        _path_values(rpm["d"])[1], omega[np.isfinite(omega)] / 6.0, atol=0.0051
    )
    # Drops: a dot per revolution that lost packets, at the count lost (own axis).
    drops = next(a for kind, a in page.paths if kind == "lidar-drops")
    lost = audit.revolutions.dropped_packets
    assert int(drops["data-n"]) == (lost > 0).sum() > 0
    nums = [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?", drops["d"])]
    np.testing.assert_allclose(-np.array(nums[1::4]), lost[lost > 0])
    # The clock: host - sensor per revolution, and its rolling minimum over a second.
    host, low = [a for kind, a in page.paths if kind == "lidar-clock"]
    raw = audit.revolutions.zero_packet_driver_ns - audit.revolutions.zero_packet_sensor_ns
    np.testing.assert_allclose(_path_values(host["d"])[1], raw / 1e3, atol=0.0051)
    # 10 s at 10 Hz: 100 revolutions (the sample's first 100 points hold the minimum so far).
    assert re.fullmatch(
        r"minimum over 100 revolutions \(9\.\d+ s\): the offset, t1 jitter removed",
        low["data-label"],
    ), low["data-label"]
    expected = [raw[max(0, i - 99) : i + 1].min() / 1e3 for i in range(raw.size)]
    np.testing.assert_allclose(_path_values(low["d"])[1], expected, atol=0.0051)


def test_log_text_is_escaped(hostile_audit: AuditResult, hostile: str) -> None:
    page_text = render_audit_html(hostile_audit)
    page = _parse(page_text)
    assert page.tags.count("script") == 1
    text = " ".join(page.text)
    assert f"camera cam{hostile}" in text  # shown as text, entity included literally
    assert f"/lidar{hostile}" in text and f"frame id {hostile} unknown" in text


def test_combined_report_of_audit_and_calibration(audit: AuditResult, calibration: Load) -> None:
    ok = calibration("calib_turntable_32")
    page = _parse(render_report_html(audit, ok))
    kinds = [k for k, _ in page.figures]
    assert kinds.count("error") == 3 and kinds.count("mounts") == 1
    assert kinds.count("pair-residuals") == len([lidar for lidar in ok.lidars if lidar.pairs])
    degenerate = [
        p for lidar in ok.lidars for p in lidar.pairs if "degenerate" in (p.alignment.reason or "")
    ]
    assert len(degenerate) == 1  # stops 3-5 of the front LiDAR: one wall in view
    assert kinds.count("degenerate") == 1
    mounts = next(a for k, a in page.figures if k == "mounts")
    assert int(mounts["data-n"]) == len(ok.extrinsics)
    refused = calibration("calib_ground_and_wall")
    page = _parse(render_report_html(None, refused))
    kinds = [k for k, _ in page.figures]
    # Refused before any alignment and without a structured direction: nothing to draw
    # (the reasons' text is not parsed); the scene's direction is drawn when the field is set.
    assert "degenerate" not in kinds and "scene-degeneracy" not in kinds
    assert "error" not in kinds and "NOT CALIBRATABLE" in " ".join(page.text)
    free = DegeneracyOut(
        kind="translation",
        direction=(-0.70, 0.71, 0.0),
        frame="base_link",
        information=0.002,
        limit=0.01,
    )
    kinds = [
        k
        for k, _ in _parse(
            render_report_html(None, refused.model_copy(update={"degeneracy": free}))
        ).figures
    ]
    assert kinds.count("scene-degeneracy") == 1


def test_cli_html_parquet_and_calibration(tmp_path: Path, calibration: Load) -> None:
    calib = tmp_path / "calib.json"
    calib.write_text(json.dumps(calibration("calib_turntable_32").to_json_dict(), indent=2))
    out = tmp_path / "report.html"
    result = CliRunner().invoke(
        app,
        [
            "audit",
            str(THREE_CAMERAS),
            "--rig",
            f"{THREE_CAMERAS}.rig.yaml",
            "--html",
            str(out),
            "--calibration",
            str(calib),
            "--calibration-any-log",  # the turntable session is another log
            "--parquet",
            str(tmp_path / "frames.parquet"),
            "--json",
        ],
    )
    assert result.exit_code == 0, result.output
    kinds = [k for k, _ in _parse(out.read_text()).figures]
    assert kinds.count("error") == 3 and kinds.count("mounts") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "calib.json",
        "frames.cameras.parquet",
        "frames.parquet",
        "report.html",
    ]
    (tmp_path / "frames.parquet").unlink()  # the summary alone still blocks a rerun
    again = CliRunner().invoke(
        app, ["audit", str(THREE_CAMERAS), "--parquet", str(tmp_path / "frames.parquet")]
    )
    assert again.exit_code == 8 and "--overwrite" in again.output, again.output
    assert not (tmp_path / "frames.parquet").exists()
    calib.write_text('{"kind": "something else"}')
    bad = CliRunner().invoke(
        app,
        [
            "audit",
            str(THREE_CAMERAS),
            "--html",
            str(tmp_path / "x.html"),
            "--calibration",
            str(calib),
        ],
    )
    assert bad.exit_code == 6, bad.output
    assert "not a calibration result" in bad.output and "Traceback" not in bad.output
    assert not (tmp_path / "x.html").exists()


def test_no_none_in_a_calibration_without_reference_stop(calibration: Load) -> None:
    """The console said "reference lidar_front at stop None" for a session never anchored."""
    import io

    from rich.console import Console

    from syncaudit.report.calib_section import html_section, render_calibration

    refused = calibration("calib_turntable_32").model_copy(update={"reference_stop": None})
    buffer = io.StringIO()
    render_calibration(refused, Console(file=buffer, width=200))
    console_text = buffer.getvalue()
    section = html_section(refused)
    for text in (console_text, section):
        assert "None" not in text
        assert "no stop anchored" in text
    anchored = calibration("calib_turntable_32")
    assert "at stop 0" in html_section(anchored)
