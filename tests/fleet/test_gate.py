"""`syncaudit gate` end to end on the sample logs: outputs, exit codes, broken logs and workers."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import junitparser
import pytest
from typer.testing import CliRunner

from marks import write_ours
from syncaudit.cli import app
from syncaudit.fleet.gate import GateOptions, run_gate
from syncaudit.fleet.policy import parse_policy

from .conftest import SAMPLES, THREE_CAMERAS

POLICY = {
    "vehicle_pattern": r"uploads/(?P<vehicle>[^/]+)/",
    "defaults": {
        "camera": {"error_mean_us": {"max": 2500}, "error_var_us2": {"max": 1e7}},
        "lidar": {"rpm": {"min": 500, "max": 700}},
    },
    # car1's Eq. 5 limit is tighter than its measured 1605 us (front camera): car1 fails.
    "vehicles": {"car1": {"cameras": {"front": {"error_mean_us": {"max": 1000}}}}},
}


def _write_policy(tmp_path: Path, raw: dict[str, object] = POLICY) -> Path:
    path = tmp_path / "policy.yaml"
    path.write_text(json.dumps(raw))
    return path


def test_gate_outputs_on_a_two_vehicle_fleet(small_fleet: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    policy = _write_policy(tmp_path)
    result = CliRunner().invoke(
        app,
        [
            "gate",
            str(small_fleet),
            "--policy",
            str(policy),
            "--db",
            str(out / "fleet.duckdb"),
            "--junit",
            str(out / "gate.xml"),
            "--summary",
            str(out / "gate.md"),
            "--json-out",
            str(out / "gate.json"),
            "--html",
            str(out / "html"),
            "--jobs",
            "2",
        ],
    )
    assert result.exit_code == 10, result.output
    summary = json.loads((out / "gate.json").read_text())
    # car2's Pandar clock is not synchronised to the host: the default `warn` check.
    assert summary["counts"] == {"fail": 1, "error": 0, "warn": 1, "pass": 0}
    by_vehicle = {log["vehicle"]: log for log in summary["logs"]}
    assert by_vehicle["car1"]["verdict"] == "fail" and by_vehicle["car2"]["verdict"] == "warn"
    warned = [c["check"] for c in by_vehicle["car2"]["checks"] if not c["passed"]]
    assert warned == ["clock_synchronised"]
    failed = [c for c in by_vehicle["car1"]["checks"] if not c["passed"]]
    assert [(c["subject"], c["check"], c["limit"]) for c in failed] == [
        ("front", "error_mean_us", "<= 1000")
    ]
    assert failed[0]["value"] == pytest.approx(1605.04, abs=0.01)

    # JUnit read back by a JUnit parser: one suite per log, one case per check.
    xml = junitparser.JUnitXml.fromfile(str(out / "gate.xml"))
    suites = {suite.name: suite for suite in xml}
    assert len(suites) == 2
    car1 = next(s for name, s in suites.items() if "/car1/" in name)
    cases = list(car1)
    assert car1.tests == len(cases) == len(by_vehicle["car1"]["checks"])
    failures = [c for c in cases if not c.is_passed]
    assert len(failures) == 1 and failures[0].name == "front: error_mean_us"
    message = failures[0].result[0].message
    assert "1605.04 us" in message and "<= 1000 us" in message
    assert xml.failures == 1 and xml.errors == 0

    markdown = (out / "gate.md").read_text()
    assert markdown.index("## Failing logs") < markdown.index("## All logs")
    assert "front: error_mean_us | 1605.04 us | <= 1000 us" in markdown

    index = (out / "html" / "index.html").read_text()
    reports = sorted((out / "html" / "logs").glob("*.html"))
    assert len(reports) == 2 and all(f'href="logs/{r.name}"' in index for r in reports)
    assert "Policy checks" in reports[0].read_text()

    # Re-run: both logs unchanged -> taken from the database, byte-identical JSON summary.
    again = run_gate(
        [str(small_fleet)],
        parse_policy(POLICY, "p"),
        GateOptions(db=out / "fleet.duckdb", json_out=out / "again.json"),
    )
    assert all(log.skipped for log in again.logs) and again.exit_code == 10
    assert (out / "again.json").read_bytes() == (out / "gate.json").read_bytes()
    forced = run_gate(
        [str(small_fleet)],
        parse_policy(POLICY, "p"),
        GateOptions(db=out / "fleet.duckdb", json_out=out / "forced.json", force=True, jobs=1),
    )
    assert not any(log.skipped for log in forced.logs)
    assert (out / "forced.json").read_bytes() == (out / "gate.json").read_bytes()
    # A changed policy is a new verdict: judged again.
    looser = {**POLICY, "vehicles": {}}
    changed = run_gate(
        [str(small_fleet)], parse_policy(looser, "p"), GateOptions(db=out / "fleet.duckdb")
    )
    assert not any(log.skipped for log in changed.logs) and changed.exit_code == 0

    import duckdb

    with duckdb.connect(str(out / "fleet.duckdb"), read_only=True) as con:
        assert con.execute("SELECT count(*) FROM logs").fetchone() == (4,)
        assert con.execute("SELECT count(DISTINCT camera) FROM cameras").fetchone() == (3,)
        row = con.execute(
            "SELECT c.error_mean_us FROM cameras c JOIN logs l USING (log_key) "
            "WHERE l.vehicle = 'car1' AND c.camera = 'front' LIMIT 1"
        ).fetchone()
        assert row is not None and row[0] == pytest.approx(1605.04, abs=0.01)


def test_corrupt_log_dying_worker_and_hung_log_become_error_rows(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    fleet = tmp_path / "logs"
    fleet.mkdir()
    shutil.copy(THREE_CAMERAS, fleet / "good.mcap")
    shutil.copy(str(THREE_CAMERAS) + ".rig.yaml", fleet / "good.mcap.rig.yaml")
    data = bytearray(THREE_CAMERAS.read_bytes())
    middle = len(data) // 2
    data[middle : middle + 4096] = bytes(range(256)) * 16  # inside a zstd chunk
    (fleet / "corrupt.mcap").write_bytes(data)
    (fleet / "crashme.mcap").symlink_to(THREE_CAMERAS)
    (fleet / "hangme.mcap").symlink_to(SAMPLES / "pandar40p_adaptive.mcap")
    monkeypatch.setenv("SYNCAUDIT_FLEET_TEST_CRASH", "crashme")
    monkeypatch.setenv("SYNCAUDIT_FLEET_TEST_HANG", "hangme")
    policy = parse_policy(
        {"defaults": {"camera": {"error_mean_us": {"max": 5000}, "error_var_us2": {"max": 1e8}}}},
        "p",
    )
    run = run_gate(
        [str(fleet), str(tmp_path / "absent.mcap")],
        policy,
        GateOptions(db=tmp_path / "fleet.duckdb", jobs=2, timeout_s=3.0, max_tries=2),
    )
    rows = {Path(log.path).name: log for log in run.logs}
    assert rows["good.mcap"].verdict == "pass"
    assert rows["crashme.mcap"].verdict == "error"
    assert rows["crashme.mcap"].attempts == 2
    assert "worker died" in (rows["crashme.mcap"].error or "")
    assert rows["hangme.mcap"].verdict == "error" and "timed out after 3 s" in (
        rows["hangme.mcap"].error or ""
    )
    corrupt = rows["corrupt.mcap"]
    assert corrupt.verdict == "error" and corrupt.error_code == 3
    assert "corrupt.mcap: MCAP chunk at offset" in (corrupt.error or "")
    assert rows["absent.mcap"].verdict == "error"
    assert run.exit_code == 3
    import duckdb

    with duckdb.connect(str(tmp_path / "fleet.duckdb"), read_only=True) as con:
        verdicts = dict(
            con.execute("SELECT verdict, count(*) FROM logs GROUP BY verdict").fetchall()
        )
    assert verdicts == {"pass": 1, "error": 4}


def test_cli_exit_codes_for_policy_usage_and_outputs(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    bad = tmp_path / "bad.yaml"
    bad.write_text("defaults:\n  camera:\n    eror_mean_us: {max: 1}\n  lidar:\n    rpm: {mn: 3}\n")
    result = runner.invoke(app, ["gate", str(THREE_CAMERAS), "--policy", str(bad), "--no-db"])
    assert result.exit_code == 6
    assert "defaults.camera.eror_mean_us: unknown key" in result.output
    assert "defaults.lidar.rpm.mn: unknown key" in result.output
    assert runner.invoke(app, ["gate", str(THREE_CAMERAS)]).exit_code == 64
    assert runner.invoke(app, ["gate", "--init", str(THREE_CAMERAS)]).exit_code == 64
    good = _write_policy(
        tmp_path,
        {"defaults": {"camera": {"error_mean_us": {"max": 5000}, "error_var_us2": {"max": 1e8}}}},
    )
    existing = tmp_path / "gate.xml"
    kept = write_ours(existing, "keep")  # an earlier run's JUnit file
    result = runner.invoke(
        app,
        ["gate", str(THREE_CAMERAS), "--policy", str(good), "--no-db", "--junit", str(existing)],
    )
    assert result.exit_code == 8 and "--overwrite" in result.output
    assert existing.read_text() == kept
    result = runner.invoke(app, ["gate", str(THREE_CAMERAS), "--policy", str(good), "--no-db"])
    assert result.exit_code == 0, result.output
    assert not (tmp_path / "fleet.duckdb").exists()  # --no-db records nothing


def test_the_documented_set_up_command_runs_as_written(tmp_path: Path) -> None:
    """README's and docs/fleet.md's fleet command, on a copy of sample_logs: all under one folder."""
    import subprocess
    import sys

    repo = SAMPLES.parent
    readme = (repo / "README.md").read_text()
    command = readme.split("## Fleet gate", 1)[1].split("```sh\n", 1)[1].split("\n```", 1)[0]
    assert command in (repo / "docs" / "fleet.md").read_text()
    assert "pip install" not in command  # it must not replace an editable install
    (tmp_path / "sample_logs").symlink_to(SAMPLES)
    bindir = Path(sys.executable).parent
    env = {"PATH": f"{bindir}:/usr/bin:/bin", "HOME": str(tmp_path)}
    done = subprocess.run(
        ["bash", "-c", command], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr
    demo = tmp_path / "fleet-demo"
    summary = json.loads((demo / "gate.json").read_text())
    assert summary["counts"]["pass"] == 4
    assert (demo / "dashboard" / "index.html").is_file()
    assert len((demo / "fleet.csv").read_text().splitlines()) == 1 + 4 * 3
    # Nothing outside fleet-demo/, no lock or temporary left inside it.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fleet-demo", "sample_logs"]
    assert sorted(p.name for p in demo.iterdir()) == [
        ".fleet.csv.syncaudit",
        "dashboard",
        "fleet.csv",
        "fleet.duckdb",
        "gate-html",
        "gate.json",
        "gate.md",
        "gate.xml",
        "policy.yaml",
    ]


def test_executor_sizing_shares_cores_only_between_few_logs() -> None:
    from syncaudit.fleet.gate import make_executor

    many, per_log = make_executor(GateOptions(jobs=4), 100)
    assert (many.workers, per_log) == (4, 1)  # type: ignore[attr-defined]
    few, per_log = make_executor(GateOptions(jobs=4), 2)
    assert (few.workers, per_log) == (2, 2)  # type: ignore[attr-defined]
    one, per_log = make_executor(GateOptions(jobs=4), 1)
    assert (one.workers, per_log) == (1, 4)  # type: ignore[attr-defined]


def test_two_copies_of_one_log_are_two_rows(tmp_path: Path) -> None:
    for name in ("a.mcap", "b.mcap"):
        (tmp_path / name).symlink_to(THREE_CAMERAS)
    policy = parse_policy(
        {"defaults": {"camera": {"error_mean_us": {"max": 5000}, "error_var_us2": {"max": 1e8}}}},
        "p",
    )
    run = run_gate([str(tmp_path)], policy, GateOptions(db=tmp_path / "f.duckdb", jobs=2))
    assert [Path(log.path).name for log in run.logs] == ["a.mcap", "b.mcap"]
    assert run.logs[0].fingerprint == run.logs[1].fingerprint
    assert run.logs[0].key != run.logs[1].key


def test_error_rows_are_tried_again_on_the_next_run(tmp_path: Path) -> None:
    data = bytearray(THREE_CAMERAS.read_bytes())
    data[len(data) // 2 : len(data) // 2 + 4096] = bytes(4096)
    (tmp_path / "corrupt.mcap").write_bytes(data)
    policy = parse_policy({}, "p")
    options = GateOptions(db=tmp_path / "f.duckdb", jobs=1)
    first = run_gate([str(tmp_path / "corrupt.mcap")], policy, options)
    second = run_gate([str(tmp_path / "corrupt.mcap")], policy, options)
    assert first.logs[0].verdict == second.logs[0].verdict == "error"
    assert not second.logs[0].skipped and first.exit_code == second.exit_code == 3
