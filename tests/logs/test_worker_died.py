"""A reader worker that dies mid-read (the OOM killer's SIGKILL, a crash) ends the run with
one line saying how it died and the exit code that fits, never exit 70 for a kill.

The kill is real: `os.kill` on the pid of one of the pool's worker processes while the
chunk-parallel read runs; the crash cases are real processes that crash or exit.
"""

from __future__ import annotations

import faulthandler
import multiprocessing
import os
import signal
import time
from pathlib import Path

import pytest

from slowed_cli import reaped, start, survivors, wait_for_workers, worker_killed_line
from syncaudit.errors import EXIT_INTERNAL, EXIT_INTERRUPTED, WorkerDiedError
from syncaudit.workers import death_cause

REPO = Path(__file__).resolve().parents[2]
LOG = REPO / "sample_logs" / "pandar40p_adaptive.mcap"
"""Seven zstd chunks: seven tasks with one chunk per task."""


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs Linux /proc")
def test_worker_killed_mid_read_is_one_line_and_exit_130(tmp_path: Path) -> None:
    """SIGKILL to a worker (what the OOM killer sends) mid-read: exit 130, one line naming
    the log and the signal, no traceback, no output file, no worker left alive."""
    json_out = tmp_path / "audit.json"
    proc = start(
        ["audit", str(LOG), "--rig", f"{LOG}.rig.yaml", "--jobs", "2", "--json-out", str(json_out)],
        sleep_s=0.5,  # the read lasts seconds: a worker can be killed while it runs
        tasks_per_worker=1,
    )
    with reaped(proc):
        workers = wait_for_workers(proc, 2, poll_s=0.02)
        assert len(workers) == 2, "the pool's two workers never started"
        time.sleep(0.3)  # both are now inside their first task
        os.kill(workers[0], signal.SIGKILL)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == EXIT_INTERRUPTED, err
    assert err.strip().splitlines() == [worker_killed_line(LOG, "a reader worker process")]
    assert not json_out.exists()
    assert not list(tmp_path.iterdir())  # no temporary left either
    assert survivors(workers) == []


def _die(how: str) -> None:
    if how == "crash":
        faulthandler.disable()  # pytest's would print this deliberate crash's stack
        os.kill(os.getpid(), signal.SIGSEGV)
    elif how == "exit":
        os._exit(3)
    else:
        time.sleep(60)


def _dead(how: str) -> multiprocessing.process.BaseProcess:
    process = multiprocessing.get_context("fork").Process(target=_die, args=(how,))
    process.start()
    if how == "kill":
        os.kill(process.pid, signal.SIGKILL)
    process.join(10)
    return process


@pytest.mark.parametrize(
    ("how", "words", "code"),
    [
        ("kill", "killed by signal 9 — out of memory?", EXIT_INTERRUPTED),
        ("crash", "crashed with signal 11, SIGSEGV: a bug, please report it", EXIT_INTERNAL),
        ("exit", "exited with status 3", EXIT_INTERNAL),
    ],
)
def test_death_cause_names_how_the_worker_died(how: str, words: str, code: int) -> None:
    """The dead worker is told apart from the others the pool SIGTERMs after it."""
    dead = _dead(how)
    terminated = multiprocessing.get_context("fork").Process(target=_die, args=("sleep",))
    terminated.start()
    terminated.terminate()
    terminated.join(10)
    said, exit_code = death_cause([terminated, dead])
    assert said.startswith(words)
    assert exit_code == code


def test_worker_died_error_keeps_its_exit_code_across_pickling() -> None:
    """Fleet workers send errors back pickled: a crash stays 70, a kill 130."""
    import pickle

    crash = pickle.loads(pickle.dumps(WorkerDiedError("x", exit_code=EXIT_INTERNAL)))
    assert (str(crash), crash.exit_code) == ("x", EXIT_INTERNAL)
    kill = pickle.loads(pickle.dumps(WorkerDiedError("y")))
    assert (str(kill), kill.exit_code) == ("y", EXIT_INTERRUPTED)


def test_death_cause_waits_for_a_status_the_pools_thread_reaped_first() -> None:
    """The pool's own thread reaps a dead worker too; when its `waitpid` wins, the status
    reaches the Process object only once that thread stores it. The SIGKILL must still be
    the cause named, not the SIGTERM the pool sent the other worker (a CI failure)."""
    import threading

    killed = multiprocessing.get_context("fork").Process(target=_die, args=("sleep",))
    killed.start()
    os.kill(killed.pid, signal.SIGKILL)
    _, status = os.waitpid(killed.pid, 0)  # what the pool's thread does first ...
    popen = killed._popen  # type: ignore[attr-defined]
    store = threading.Timer(
        0.2, lambda: setattr(popen, "returncode", os.waitstatus_to_exitcode(status))
    )
    terminated = multiprocessing.get_context("fork").Process(target=_die, args=("sleep",))
    terminated.start()
    terminated.terminate()
    terminated.join(10)
    # ... and stores a moment later: started now, so that a slow fork or join above (a
    # loaded machine) cannot let the status arrive before `death_cause` looks for it.
    store.start()
    assert killed.exitcode is None  # no status yet: `death_cause` must wait for it
    try:
        said, exit_code = death_cause([terminated, killed])
    finally:
        store.join()
    assert said.startswith("killed by signal 9 — out of memory?")
    assert exit_code == EXIT_INTERRUPTED
