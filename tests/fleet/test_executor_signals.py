"""The gate's worker processes and signals: a Ctrl-C while a worker starts never kills it,
and a driver killed outright takes its workers with it.

Ctrl-C reaches the whole process group, workers included; each ignores SIGINT (the
driver alone decides), but a worker starting when the signal came had not yet said so:
it died with a KeyboardInterrupt traceback and its log was retried or lost (a race; the
worker-pool of `syncaudit.workers` blocks the signal while it forks, and so does the
gate's executor now). The test sends the signal exactly in that window.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from syncaudit.fleet import executor as executor_module
from syncaudit.fleet.executor import LocalExecutor
from syncaudit.fleet.inputs import LogJob
from syncaudit.fleet.job import JobOptions, LogOutcome


def _done(job: LogJob, options: JobOptions) -> LogOutcome:
    """A task that takes no time: what matters is that the worker lives to run it."""
    return LogOutcome(job=job, topics=["ran"])


@pytest.mark.skipif(
    "fork" not in multiprocessing.get_all_start_methods(), reason="needs fork start method"
)
def test_a_ctrl_c_while_a_worker_starts_does_not_kill_it(
    monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]
) -> None:
    driver = os.getpid()
    real = signal.signal

    def ctrl_c_first(signum: int, handler: Any) -> Any:
        if signum == signal.SIGINT and handler is signal.SIG_IGN and os.getpid() != driver:
            os.kill(os.getpid(), signal.SIGINT)  # arrives just before the worker ignores it
        return real(signum, handler)

    # Ctrl-C raises here, as in a terminal (a runner may have started pytest ignoring it).
    previous = real(signal.SIGINT, signal.default_int_handler)
    try:
        monkeypatch.setattr(signal, "signal", ctrl_c_first)  # inherited by the forked worker
        pool = LocalExecutor(1, timeout_s=120, max_tries=1, task=_done)
        assert pool._context.get_start_method() == "fork"
        (outcome,) = list(pool.run([LogJob(path="a.mcap")], JobOptions()))
    finally:
        monkeypatch.undo()
        real(signal.SIGINT, previous)
    assert outcome.error is None and outcome.topics == ["ran"]
    assert outcome.attempts == 1
    assert "KeyboardInterrupt" not in capfd.readouterr().err
    assert executor_module.signal.signal is real


DRIVER = """
import sys, os, time
from syncaudit.fleet.executor import LocalExecutor
from syncaudit.fleet.inputs import LogJob
from syncaudit.fleet.job import JobOptions

def hang(job, options):
    with open(sys.argv[1] + ".tmp", "w") as f:
        f.write(str(os.getpid()))
    os.replace(sys.argv[1] + ".tmp", sys.argv[1])
    time.sleep(120)  # a log that hangs

list(LocalExecutor(1, timeout_s=600, task=hang).run([LogJob(path="a.mcap")], JobOptions()))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
def test_a_driver_killed_outright_leaves_no_worker(tmp_path: Path) -> None:
    """The OOM killer's SIGKILL to `syncaudit gate` ends its workers too; before, a worker
    on a hung log lived on for the log's whole timeout (found as orphans of a test run)."""
    pid_file = tmp_path / "worker.pid"
    driver = subprocess.Popen([sys.executable, "-c", DRIVER, str(pid_file)])
    try:
        deadline = time.monotonic() + 120  # the driver's imports, on a loaded machine
        while not pid_file.exists() and driver.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        assert pid_file.exists(), "the worker never ran its log"
        worker = int(pid_file.read_text())
    finally:
        driver.kill()
        driver.wait()
    deadline = time.monotonic() + 30
    while _running(worker) and time.monotonic() < deadline:
        time.sleep(0.02)
    alive = _running(worker)
    if alive:
        os.kill(worker, signal.SIGKILL)
    assert not alive, "the worker outlived its killed driver"


def _running(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] not in "ZX"
