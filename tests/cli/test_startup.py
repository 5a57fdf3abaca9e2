"""The console script's start-up pause of the garbage collector (`syncaudit.cli.startup`)."""

from __future__ import annotations

import gc
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from syncaudit.cli.common import run
from syncaudit.cli.startup import (
    PAUSED_THRESHOLD,
    gc_paused,
    one_blas_thread,
    pause_gc,
    resume_gc,
)

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def restored_gc() -> Iterator[tuple[int, ...]]:
    """The test's collector thresholds and frozen objects put back afterwards."""
    before = gc.get_threshold()
    frozen = gc.get_freeze_count()
    yield before
    resume_gc()
    gc.set_threshold(*before)
    if frozen == 0:
        gc.unfreeze()


def test_pause_raises_the_threshold_and_resume_restores_it(
    restored_gc: tuple[int, ...],
) -> None:
    pause_gc()
    pause_gc()  # twice: still the thresholds from before the first
    assert gc_paused() and gc.get_threshold() == (PAUSED_THRESHOLD, *restored_gc[1:])
    resume_gc()
    assert not gc_paused() and gc.get_threshold() == restored_gc
    assert gc.get_freeze_count() > 0  # what start-up built is frozen


def test_resume_without_pause_changes_nothing(restored_gc: tuple[int, ...]) -> None:
    frozen = gc.get_freeze_count()
    resume_gc()
    assert gc.get_threshold() == restored_gc and gc.get_freeze_count() == frozen


def test_run_imports_while_paused_and_works_after(restored_gc: tuple[int, ...]) -> None:
    seen: list[tuple[str, bool]] = []
    pause_gc()
    run(
        lambda: seen.append(("job", gc_paused())),
        imports=lambda: seen.append(("imports", gc_paused())),
    )
    assert seen == [("imports", True), ("job", False)]
    assert gc.get_threshold() == restored_gc


SCRIPT = """
import gc, sys
import syncaudit.cli.common as common
from syncaudit.cli import main

seen = []
real_run = common.run
def spy(job, **kw):
    return real_run(lambda: (seen.append(gc.get_threshold()[0]), job())[1], **kw)
for module in ("syncaudit.cli.audit_command", "syncaudit.cli.info_command"):
    setattr(sys.modules[module], "run", spy)
real_exit = common.os._exit
def report(code):
    blas = common.os.environ.get("OPENBLAS_NUM_THREADS")
    sys.stderr.write(f"{blas} {gc.get_threshold()[0]} {seen}\\n")
    real_exit(code)
common.os._exit = report
sys.argv = ["syncaudit", *sys.argv[1:]]
main()
"""


def test_console_script_audit_works_with_the_collector_on(tmp_path: Path) -> None:
    """`syncaudit audit`: the command's body (the reading) runs with the usual thresholds,
    numpy with one OpenBLAS thread."""
    log = REPO / "sample_logs" / "vlp16_three_cameras.mcap"
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT, "audit", str(log), "--rig", f"{log}.rig.yaml", "--json"],
        capture_output=True,
        text=True,
        check=False,
        env=env,
    )
    assert done.returncode == 0, done.stderr
    blas, threshold_at_exit, seen = done.stderr.strip().splitlines()[-1].split(" ", 2)
    assert blas == "1"
    assert int(threshold_at_exit) == gc.get_threshold()[0] != PAUSED_THRESHOLD
    assert seen == f"[{threshold_at_exit}]"


def test_one_blas_thread_keeps_a_number_the_user_set(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delitem(sys.modules, "numpy", raising=False)  # as before the imports
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "4")
    one_blas_thread()
    assert os.environ["OPENBLAS_NUM_THREADS"] == "4"
    monkeypatch.delenv("OPENBLAS_NUM_THREADS")
    one_blas_thread()
    assert os.environ["OPENBLAS_NUM_THREADS"] == "1"


def test_one_blas_thread_leaves_the_environment_once_numpy_is_loaded(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Too late to matter for this process: its workers and children are not changed."""
    import numpy  # noqa: F401

    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    one_blas_thread()
    assert "OPENBLAS_NUM_THREADS" not in os.environ


COMMANDS = ["audit", "calib", "info", "rig", "gate", "simulate", "fleet"]


def test_only_command_keeps_just_the_named_command() -> None:
    import syncaudit.cli  # registers every command on `app`
    from syncaudit.cli.common import app, only_command

    assert syncaudit.cli.app is app
    for name in COMMANDS:
        only = only_command([name, "--help"])
        names = [c.callback.__name__ for c in only.registered_commands if c.callback]
        assert names + [g.name for g in only.registered_groups] == [name]
    for argv in ([], ["--help"], ["--version"], ["aud"], ["LOG.mcap"]):
        assert only_command(argv) is app  # help, version and errors see every command


@pytest.mark.parametrize("name", COMMANDS)
def test_only_command_prints_what_the_whole_app_prints(name: str) -> None:
    """Help and usage errors of a command are the same from the trimmed app."""
    from typer.testing import CliRunner

    import syncaudit.cli
    from syncaudit.cli.common import only_command

    runner = CliRunner()
    for argv in ([name, "--help"], [name, "--no-such-option"]):
        whole = runner.invoke(syncaudit.cli.app, argv)
        trimmed = runner.invoke(only_command(argv), argv)
        assert (trimmed.exit_code, trimmed.output) == (whole.exit_code, whole.output)
