"""Gate outputs through one OutputSet: checked before any work, committed together, and an
interrupted run leaves no temporary and the previous files as they were."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from marks import write_ours
from slowed_cli import foreground
from syncaudit.cli import app
from syncaudit.errors import OutputError, UsageError
from syncaudit.fleet.gate import GateOptions, run_gate
from syncaudit.fleet.policy import parse_policy

from .conftest import SAMPLES, THREE_CAMERAS

LOOSE = {"defaults": {"camera": {"error_mean_us": {"max": 5000}, "error_var_us2": {"max": 1e8}}}}


def _policy_file(tmp_path: Path) -> Path:
    path = tmp_path / "policy.json"
    path.write_text(json.dumps(LOOSE))
    return path


def _snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under `folder` (hidden ones too) with its bytes."""
    return {
        str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()
    }


def _temporaries(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if p.name.startswith(".syncaudit-")]


@pytest.mark.parametrize("option", ["--junit", "--summary", "--json-out", "--html"])
def test_an_existing_target_is_refused_before_any_work(option: str, tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    target = out / "target"
    if option == "--html":  # an earlier run's outputs (they carry the tool's mark)
        target.mkdir()
        write_ours(target / "index.html")
    else:
        write_ours(target)
    before = _snapshot(out)
    result = CliRunner().invoke(
        app,
        [
            "gate",
            str(THREE_CAMERAS),
            "--policy",
            str(_policy_file(tmp_path)),
            "--db",
            str(out / "fleet.duckdb"),
            "--json-out" if option != "--json-out" else "--summary",
            str(out / "other"),
            option,
            str(target),
        ],
    )
    assert result.exit_code == 8, result.output
    assert f"error: {target}: exists" in result.output and "--overwrite" in result.output
    # Nothing was done: no database, no other output, no temporary, the target unchanged.
    assert _snapshot(out) == before


@pytest.mark.parametrize("option", ["--junit", "--summary", "--json-out", "--html"])
def test_a_target_the_tool_did_not_write_is_refused_whatever_the_flags(
    option: str, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    out.mkdir()
    target = out / "target"
    if option == "--html":  # a user's own index.html
        target.mkdir()
        (target / "index.html").write_text("previous")
    else:
        target.write_text("previous")
    before = _snapshot(out)
    result = CliRunner().invoke(
        app,
        ["gate", str(THREE_CAMERAS), "--policy", str(_policy_file(tmp_path)), "--no-db",
         option, str(target), "--overwrite"],
    )  # fmt: skip
    assert result.exit_code == 8, result.output
    assert "did not write" in result.output and "--overwrite" not in result.output
    assert _snapshot(out) == before


def test_init_policy_target_is_checked_first_and_never_an_input(tmp_path: Path) -> None:
    runner = CliRunner()
    policy = tmp_path / "policy.yaml"
    previous = write_ours(policy)
    result = runner.invoke(app, ["gate", "--init", str(THREE_CAMERAS), "-o", str(policy)])
    assert result.exit_code == 8 and "--overwrite" in result.output
    assert policy.read_text() == previous
    log = tmp_path / "good.mcap"
    log.write_bytes(THREE_CAMERAS.read_bytes())
    result = runner.invoke(app, ["gate", "--init", str(log), "-o", str(log), "--overwrite"])
    assert result.exit_code == 64 and "is an input of this run" in result.output
    assert log.read_bytes() == THREE_CAMERAS.read_bytes()
    result = runner.invoke(  # the sample fails the defaults: refused, nothing written
        app, ["gate", "--init", str(THREE_CAMERAS), "-o", str(policy), "--overwrite"]
    )
    assert result.exit_code == 10 and policy.read_text() == previous
    assert not _temporaries(tmp_path)
    result = runner.invoke(
        app,
        ["gate", "--init", str(THREE_CAMERAS), "-o", str(policy), "--overwrite", "--accept-bad"],
    )
    assert result.exit_code == 0, result.output
    assert "error_mean_us" in policy.read_text() and not _temporaries(tmp_path)


def test_an_html_folder_that_is_not_a_gate_report_is_never_written_into(tmp_path: Path) -> None:
    folder = tmp_path / "site"
    folder.mkdir()
    (folder / "notes.txt").write_text("mine")
    with pytest.raises(OutputError, match="not a gate report folder"):
        run_gate(
            [str(THREE_CAMERAS)],
            parse_policy(LOOSE, "p"),
            GateOptions(html_dir=folder, overwrite=True),
        )
    assert _snapshot(folder) == {"notes.txt": b"mine"}
    with pytest.raises(UsageError, match="is an input of this run"):
        run_gate(
            [str(tmp_path)],
            parse_policy(LOOSE, "p"),
            GateOptions(junit=tmp_path / "policy.json", policy_path=tmp_path / "policy.json"),
        )


def test_reports_are_added_to_a_gate_folder_and_a_lost_report_is_made_again(
    tmp_path: Path,
) -> None:
    policy = parse_policy(LOOSE, "p")
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in ("a.mcap", "b.mcap"):
        (logs / name).symlink_to(THREE_CAMERAS)
        (logs / f"{name}.rig.yaml").symlink_to(f"{THREE_CAMERAS}.rig.yaml")
    html, db = tmp_path / "html", tmp_path / "fleet.duckdb"
    first = run_gate([str(logs)], policy, GateOptions(db=db, html_dir=html, jobs=1))
    reports = sorted(p.name for p in (html / "logs").iterdir())
    assert len(reports) == 2 and all(log.report for log in first.logs)
    lost = html / "logs" / reports[0]
    lost.unlink()
    with pytest.raises(OutputError, match="--overwrite"):
        run_gate([str(logs)], policy, GateOptions(db=db, html_dir=html))
    second = run_gate([str(logs)], policy, GateOptions(db=db, html_dir=html, overwrite=True))
    # The log whose report was lost is judged again (its report made again); the other
    # is taken from the database and linked to its earlier report.
    assert sorted(log.skipped for log in second.logs) == [False, True]
    assert lost.is_file() and sorted(p.name for p in (html / "logs").iterdir()) == reports
    index = (html / "index.html").read_text()
    assert all(f'href="logs/{name}"' in index for name in reports)
    assert not _temporaries(tmp_path)


def _wait_for(path: Path, text: str, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if path.exists() and text in path.read_text():
            return
        time.sleep(0.05)
    raise AssertionError(f"{text!r} never appeared in {path}: {path.read_text()!r}")


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupted_run_leaves_no_temporary_and_the_previous_outputs(
    signum: int, tmp_path: Path
) -> None:
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "a_good.mcap").symlink_to(THREE_CAMERAS)
    (logs / "a_good.mcap.rig.yaml").symlink_to(f"{THREE_CAMERAS}.rig.yaml")
    (logs / "z_hangme.mcap").symlink_to(SAMPLES / "pandar40p_adaptive.mcap")
    (logs / "z_hangme.mcap.rig.yaml").symlink_to(SAMPLES / "pandar40p_adaptive.mcap.rig.yaml")
    out = tmp_path / "out"
    out.mkdir()
    argv = [
        sys.executable,
        "-m",
        "syncaudit.cli",
        "gate",
        str(logs),
        "--policy",
        str(_policy_file(tmp_path)),
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
        "1",
    ]
    first = subprocess.run(argv, capture_output=True, text=True, timeout=120)
    assert first.returncode == 0, first.stderr  # a pass and a warn (pandar's clock)
    before = _snapshot(out)
    assert {"gate.xml", "gate.md", "gate.json", "html/index.html"} <= set(before)

    stderr = tmp_path / "stderr.txt"
    env = {**os.environ, "SYNCAUDIT_FLEET_TEST_HANG": "z_hangme"}
    with stderr.open("w") as err:
        proc = subprocess.Popen(
            foreground([*argv, "--overwrite", "--force"]),
            stdout=subprocess.DEVNULL,
            stderr=err,
            env=env,
        )
        try:
            _wait_for(stderr, "[1/2] pass")  # the good log is judged, the other hangs
            assert _temporaries(out)  # the run is writing its outputs aside
            proc.send_signal(signum)
            code = proc.wait(timeout=60)
        finally:
            proc.kill()
    assert code == 130, stderr.read_text()
    assert "error: interrupted" in stderr.read_text()
    after = _snapshot(out)
    assert not _temporaries(out)
    # Every file output is byte for byte the previous run's (the database is no file
    # output: it keeps whatever verdicts it was given before the interrupt).
    assert {k: v for k, v in after.items() if "duckdb" not in k} == {
        k: v for k, v in before.items() if "duckdb" not in k
    }
