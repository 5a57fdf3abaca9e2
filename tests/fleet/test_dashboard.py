"""`fleet report`: the dashboard rendered in a real headless Chromium, and the exports."""

from __future__ import annotations

import csv
import re
import time
from pathlib import Path

import duckdb
import pytest

from browser import needs_chromium, render, screenshot
from marks import write_ours
from syncaudit.fleet.checks import CheckResult
from syncaudit.fleet.dashboard import write_report
from syncaudit.fleet.database import ResultsDB
from syncaudit.fleet.inputs import LogJob
from syncaudit.fleet.job import LogOutcome
from syncaudit.fleet.record import JudgedLog

DAY_NS = 86_400 * 10**9


def _fleet_db(tmp_path: Path, outcome: LogOutcome) -> Path:
    """Five days of one real audit per vehicle, Eq. 5 drifting up on car2 (last day fails 3000 us)."""
    db = tmp_path / "fleet.duckdb"
    reports = tmp_path / "reports"
    reports.mkdir()
    logs = []
    now_ns = time.time_ns() - 3600 * 10**9
    for vehicle in ("car1", "car2"):
        for day in range(5):
            audit = dict(outcome.audit or {})
            drift = 1.0 + (0.25 * day if vehicle == "car2" else 0.0)
            audit["cameras"] = [
                {**cam, "error_mean_us": cam["error_mean_us"] * drift} for cam in audit["cameras"]
            ]
            key = f"{vehicle}-{day}"
            report = reports / f"{key}.html"
            report.write_text(f"<html><body>{key}</body></html>")
            checks = [
                CheckResult(
                    "camera",
                    cam["camera"],
                    "error_mean_us",
                    cam["error_mean_us"],
                    "<= 3000",
                    "us",
                    "fail",
                    cam["error_mean_us"] <= 3000,
                    "",
                    None,
                    3000.0,
                )
                for cam in audit["cameras"]
            ]
            failed = not all(c.passed for c in checks)
            logs.append(
                JudgedLog(
                    job=LogJob(path=f"/uploads/{vehicle}/day{day}.mcap", vehicle=vehicle),
                    key=key,
                    fingerprint=key,
                    rig_fingerprint=None,
                    policy_fingerprint="p",
                    tool_version="t",
                    verdict="fail" if failed else "pass",
                    checks=checks,
                    audit=audit,
                    start_ns=now_ns - (4 - day) * DAY_NS,
                    report=str(report),
                )
            )
    ResultsDB(db).write(logs)
    return db


def test_exports_hold_the_same_rows(tmp_path: Path, three_cameras_outcome: LogOutcome) -> None:
    db = _fleet_db(tmp_path, three_cameras_outcome)
    write_report(db, parquet=tmp_path / "fleet.parquet", csv=tmp_path / "fleet.csv")
    rows = list(csv.DictReader((tmp_path / "fleet.csv").open()))
    assert len(rows) == 2 * 5 * 3
    with duckdb.connect() as con:
        parquet = con.execute(
            f"SELECT count(*), max(error_mean_us) FROM '{tmp_path / 'fleet.parquet'}'"
        ).fetchone()
    assert parquet is not None and parquet[0] == 30
    assert parquet[1] == pytest.approx(max(float(r["error_mean_us"]) for r in rows))
    assert not list(tmp_path.glob(".*.tmp"))


@needs_chromium
def test_dashboard_renders_in_headless_chromium(
    tmp_path: Path, three_cameras_outcome: LogOutcome
) -> None:
    db = _fleet_db(tmp_path, three_cameras_outcome)
    out = tmp_path / "dashboard"
    write_report(db, html_dir=out)
    page = (out / "index.html").read_text()
    assert "http://" not in page.replace('xmlns="http://www.w3.org/2000/svg"', "")
    assert "https://" not in page and "<link" not in page and " src=" not in page  # self-contained
    shown = render(out / "index.html")
    shot = screenshot(out / "index.html", "fleet/dashboard.png", width=1280, height=2400)
    print(f"dashboard screenshot: {shot}")
    assert shown.console == [], shown.console
    html = shown.dom
    assert 'data-ready="yes"' in html  # the inline script ran to its end
    assert len(re.findall(r'<section class="vehicle"', html)) == 2
    assert len(re.findall(r'<svg class="plot"', html)) == 2 * 3 * 3
    assert len(re.findall(r'class="limit"', html)) == 2 * 3  # Eq. 5 limit on each camera
    failing = re.findall(r'<a class="fail" href="([^"]+)"', html)
    assert len(failing) == 3 and all(f.endswith("car2-4.html") for f in failing)
    assert (out / failing[0]).resolve().is_file()
    assert shot.stat().st_size > 10_000 and shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_documented_queries_answer_on_a_fleet_database(
    tmp_path: Path, three_cameras_outcome: LogOutcome
) -> None:
    db = _fleet_db(tmp_path, three_cameras_outcome)
    docs = (Path(__file__).resolve().parents[2] / "docs" / "fleet.md").read_text()
    queries = [block.split("\n```", 1)[0] for block in docs.split("```sql\n")[1:]]
    assert len(queries) == 3
    with duckdb.connect(str(db), read_only=True) as con:
        worst, drift, failing = (con.execute(q).fetchall() for q in queries)
    # Worst cameras this week: car2's cameras first (their error grows 25 % a day).
    assert len(worst) == 6 and all(row[0] == "car2" for row in worst[:3])
    # Delay drift: one row per vehicle, camera and day; the first day has no change.
    assert len(drift) == 2 * 3 * 5 and drift[0][4] is None
    # Logs failing Eq. 5: the last day of car2, one row per camera.
    assert {(row[0], row[1]) for row in failing} == {("/uploads/car2/day4.mcap", "car2")}
    assert len(failing) == 3


def test_fleet_report_exit_codes(tmp_path: Path, three_cameras_outcome: LogOutcome) -> None:
    from typer.testing import CliRunner

    from syncaudit.cli import app

    runner = CliRunner()
    missing = runner.invoke(
        app,
        ["fleet", "report", "--db", str(tmp_path / "no.duckdb"), "--csv", str(tmp_path / "x.csv")],
    )
    assert missing.exit_code == 2 and "no such results database" in missing.output
    assert (
        runner.invoke(app, ["fleet", "report", "--db", str(tmp_path / "no.duckdb")]).exit_code == 64
    )
    db = _fleet_db(tmp_path, three_cameras_outcome)
    (tmp_path / "x.csv").write_text("keep")  # the user's own CSV: never replaced
    mine = runner.invoke(
        app, ["fleet", "report", "--db", str(db), "--csv", str(tmp_path / "x.csv"), "--overwrite"]
    )
    assert mine.exit_code == 8 and "did not write" in mine.output
    assert (tmp_path / "x.csv").read_text() == "keep"
    write_ours(tmp_path / "x.csv", "keep")  # an earlier export: --overwrite replaces it
    exists = runner.invoke(
        app, ["fleet", "report", "--db", str(db), "--csv", str(tmp_path / "x.csv")]
    )
    assert exists.exit_code == 8 and (tmp_path / "x.csv").read_text() == "keep\n"
    done = runner.invoke(
        app, ["fleet", "report", "--db", str(db), "--csv", str(tmp_path / "x.csv"), "--overwrite"]
    )
    assert done.exit_code == 0 and len((tmp_path / "x.csv").read_text().splitlines()) == 31


def test_fleet_report_outputs_are_all_or_nothing(
    tmp_path: Path, three_cameras_outcome: LogOutcome
) -> None:
    """Every target checked before the database is read; none written when one is refused."""
    from syncaudit.errors import OutputError, UsageError

    db = _fleet_db(tmp_path, three_cameras_outcome)
    site = tmp_path / "site"
    site.mkdir()
    (site / "index.html").write_text("previous")  # the user's own page: never replaced
    with pytest.raises(
        OutputError,
        match=r"site: is an existing folder that is not a dashboard folder \(its index\.html is a file syncaudit did not write",
    ):
        write_report(db, html_dir=site, csv=tmp_path / "fleet.csv", overwrite=True)
    write_ours(site / "index.html")  # an earlier dashboard
    with pytest.raises(OutputError, match=r"index.html: exists \(use --overwrite"):
        write_report(db, html_dir=site, csv=tmp_path / "fleet.csv")
    assert not (tmp_path / "fleet.csv").exists()
    assert sorted(p.name for p in site.iterdir()) == ["index.html"]
    with pytest.raises(UsageError, match="is an input of this run"):
        write_report(db, csv=db, overwrite=True)
    write_report(db, html_dir=site, csv=tmp_path / "fleet.csv", overwrite=True)
    assert "<svg" in (site / "index.html").read_text() and (tmp_path / "fleet.csv").is_file()
    assert not [p for p in tmp_path.rglob(".syncaudit-*")]


def test_failing_points_keep_their_colour_and_delays_fill_the_axis(
    tmp_path: Path, three_cameras_outcome: LogOutcome
) -> None:
    """Issue 23 finding 7: a failing log's points were all red (recommended, applied and
    t1..t4 alike), and the delay axis started at 0 (a 1.5 ms gap on 16 ms: ~14 px)."""
    from syncaudit.fleet.dashboard import COLOURS

    db = _fleet_db(tmp_path, three_cameras_outcome)
    out = tmp_path / "dashboard"
    write_report(db, html_dir=out)
    page = (out / "index.html").read_text()
    car2 = page.split('data-vehicle="car2"', 1)[1]
    front = car2.split('data-camera="front"', 1)[1].split('<div class="camera"', 1)[0]
    delay, latencies = re.findall(r'<svg class="plot".*?</svg>', front, re.S)[1:3]
    for svg, names in ((delay, ["recommended", "applied"]), (latencies, ["t1", "t2", "t3", "t4"])):
        for index, name in enumerate(names):
            dots = re.findall(rf'<circle class="(\w+)"[^>]*fill="([^"]+)"[^>]*><title>{name}:', svg)
            assert {fill for _, fill in dots} == {COLOURS[index]}, (name, dots)
            assert [cls for cls, _ in dots].count("failed") == 1  # the last day of car2
    assert 'stroke="#b00020"' in delay and "ringed in red" in car2
    # Recommended 14203.6 us, applied 15703.9 us: the gap spans most of the plot's height.
    recommended, applied = (
        {float(y) for y in re.findall(rf'cy="([\d.]+)"[^>]*><title>{name}:', delay)}
        for name in ("recommended", "applied")
    )
    assert len(recommended) == len(applied) == 1
    plot_height = 200 - 16 - 28
    assert abs(recommended.pop() - applied.pop()) > 0.6 * plot_height
