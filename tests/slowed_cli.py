"""The real `syncaudit` CLI with its reader workers slowed down, and its processes watched.

Tests that signal or kill the audit while its worker processes read need that phase to
last seconds on any machine: `start` runs the CLI in a new process group (as a shell runs
a command) with one chunk per task and each task held `sleep_s` in its worker.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

_SCRIPT = """
import sys, time
import syncaudit.logs.parallel as c

c.GROUP_BYTES = 1
{tasks_per_worker}_extract = c._extract_group


def slow(*args):
    time.sleep({sleep_s!r})
    return _extract(*args)


c._extract_group = slow
from syncaudit.cli import main

sys.argv = ["syncaudit", *sys.argv[1:]]
main()
"""


_FOREGROUND = (
    "import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
    "os.execv(sys.argv[1], sys.argv[1:])"
)


def foreground(argv: list[str]) -> list[str]:
    """`argv` run with SIGINT's default action, as a shell with job control runs a
    foreground command, whatever this process inherited (a shell runs a background job,
    `cmd &` in a script, with SIGINT ignored; Python, and so the CLI, then keeps ignoring
    Ctrl-C, rightly). The command is exec'ed: its pid is the one the test signals."""
    return [sys.executable, "-c", _FOREGROUND, *argv]


def slowed_cli_script(*, sleep_s: float, tasks_per_worker: int | None = None) -> str:
    """Python source running the CLI with one chunk per task, each held `sleep_s` in its
    worker (`tasks_per_worker`: tasks in flight per worker, default the CLI's own)."""
    in_flight = "" if tasks_per_worker is None else f"c.TASKS_PER_WORKER = {tasks_per_worker}\n"
    return _SCRIPT.format(sleep_s=float(sleep_s), tasks_per_worker=in_flight)


def start(
    args: list[str], *, sleep_s: float, tasks_per_worker: int | None = None
) -> subprocess.Popen[str]:
    """`syncaudit ARGS` slowed (see `slowed_cli_script`), in its own process group."""
    return subprocess.Popen(
        foreground(
            [
                sys.executable,
                "-c",
                slowed_cli_script(sleep_s=sleep_s, tasks_per_worker=tasks_per_worker),
                *args,
            ]
        ),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,  # its own process group, as a shell gives a command
        text=True,
    )


def children(pid: int) -> list[int]:
    """The child processes of `pid` (Linux /proc; none once it is gone)."""
    try:
        text = Path(f"/proc/{pid}/task/{pid}/children").read_text()
    except OSError:
        return []
    return [int(p) for p in text.split()]


def alive(pid: int) -> bool:
    """Whether process `pid` runs (a zombie is dead, just unreaped)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def survivors(pids: list[int], *, timeout_s: float = 5.0, poll_s: float = 0.01) -> list[int]:
    """Those of `pids` still alive once none is, or `timeout_s` passed.

    Called after the CLI's pipes reached end of file: its workers inherited them, so each
    has closed them and is exiting; only its last steps in the kernel may not be done
    (a loaded machine can leave a killed process unscheduled for a moment). A worker that
    went on running would have held the pipes open, so this wait hides none.
    """
    deadline = time.monotonic() + timeout_s
    while True:
        left = [pid for pid in pids if alive(pid)]
        if not left or time.monotonic() >= deadline:
            return left
        time.sleep(poll_s)


def wait_for_workers(
    proc: subprocess.Popen[str], count: int, *, timeout_s: float = 60.0, poll_s: float = 0.01
) -> list[int]:
    """The children of `proc` once there are `count` of them (fewer where it ended first
    or `timeout_s` passed)."""
    deadline = time.monotonic() + timeout_s
    workers: list[int] = []
    while time.monotonic() < deadline and proc.poll() is None:
        workers = children(proc.pid)
        if len(workers) >= count:
            break
        time.sleep(poll_s)
    return workers


@contextlib.contextmanager
def reaped(proc: subprocess.Popen[str]) -> Iterator[subprocess.Popen[str]]:
    """`proc`, its process group killed on the way out if it still runs (a failed test
    leaves no CLI or worker behind)."""
    try:
        yield proc
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def worker_killed_line(log: Path, who: str) -> str:
    """The one line the CLI prints when the OOM killer's SIGKILL ends one of its workers."""
    return (
        f"error: {log}: {who} died (killed by signal 9 — out of memory? fewer jobs or more "
        "free memory may help)"
    )
