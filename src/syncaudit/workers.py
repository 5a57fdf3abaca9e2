"""A process pool that dies with its parent and turns any interruption into one clean exit.

Worker processes ignore SIGINT (a Ctrl-C reaches the whole process group: only the parent
acts on it, so no worker prints a traceback), take SIGTERM's default action, and on Linux
ask the kernel to kill them when their parent dies (PR_SET_PDEATHSIG), so a parent killed
outright leaves no orphan. While the pool runs, SIGTERM to the parent raises
KeyboardInterrupt like SIGINT does (the CLI exits 130 on either); the pool's workers are
then terminated at once, never waited for (a worker blocked on a pipe must not hang it).
A worker that dies under the pool (the OOM killer's SIGKILL, a crash) ends the block with
one `WorkerDiedError` saying how it died, rather than concurrent.futures'
BrokenProcessPool.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import sys
import threading
import time
from collections.abc import Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from multiprocessing.context import BaseContext
from multiprocessing.process import BaseProcess
from types import FrameType

from syncaudit.errors import EXIT_INTERNAL, EXIT_INTERRUPTED, WorkerDiedError

_PR_SET_PDEATHSIG = 1
_STOP_SIGNALS = {signal.SIGINT, signal.SIGTERM}
_CRASH_SIGNALS = {signal.SIGSEGV, signal.SIGBUS, signal.SIGABRT, signal.SIGILL, signal.SIGFPE}
"""Signals a process raises on itself when it crashes: a bug, not a kill from outside."""
_REAP_S = 1.0
"""How long to wait for a dead worker's exit status (it is dead: the pool saw its end)."""
_REAP_POLL_S = 0.01
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
"""glibc `mallopt` parameters."""
KEEP_HEAP_BYTES = 64 << 20
"""Allocations below this come from the worker's heap, and this much freed heap is kept.

A worker allocates one decompressed chunk (MBs) after another. glibc serves such sizes
with a fresh `mmap` each time and unmaps them on free, so every chunk's pages fault in
anew: on a ROS 1 lz4 bag about 0.1 CPU s per GB, a third of the decompression. Kept on the
heap, the next chunk reuses the same pages."""


PARENT_MMAP_BYTES = 128 << 10
"""In a reading parent, allocations from this size up are mapped and unmapped on free."""


def return_large_frees() -> None:
    """In the parent of a read pool: keep glibc serving large allocations by `mmap`, so
    freeing one returns its pages at once (Linux; elsewhere nothing is done).

    The parent unpickles every worker's results (MBs each) and frees them after merging;
    glibc's default raises its mmap threshold after each such free (up to 32 MB), and
    later results then come from the heap, whose freed pages stay resident: on a dense
    10-minute log the parent's peak RSS went from 188 to 145 MB with the threshold fixed
    at glibc's own default of 128 KiB (which fixing it keeps from moving).
    """
    _mallopt((_M_MMAP_THRESHOLD, PARENT_MMAP_BYTES))


def _mallopt(*settings: tuple[int, int]) -> None:
    """Set glibc `mallopt` parameters (Linux; best effort: nothing where there is none)."""
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            for parameter, value in settings:
                libc.mallopt(parameter, value)
        except (OSError, AttributeError):  # pragma: no cover - no mallopt: best effort
            pass


def _init_worker(parent_pid: int) -> None:
    """Worker start: ignore Ctrl-C, die with the parent, then accept signals again."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _mallopt((_M_MMAP_THRESHOLD, KEEP_HEAP_BYTES), (_M_TRIM_THRESHOLD, KEEP_HEAP_BYTES))
    die_with_parent(parent_pid)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _STOP_SIGNALS)


def die_with_parent(parent_pid: int) -> None:
    """In a child process: have the kernel SIGKILL it when its parent dies (Linux
    PR_SET_PDEATHSIG), so a parent killed outright (the OOM killer, `kill -9`) leaves no
    orphan working on; exit now if the parent `parent_pid` is already gone."""
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):  # pragma: no cover - no prctl: best effort
            pass
    if os.getppid() != parent_pid:  # the parent died before the prctl took hold
        os._exit(1)


def _raise_interrupt(signum: int, frame: FrameType | None) -> None:
    """SIGTERM in the parent while the pool runs: stop like Ctrl-C does."""
    raise KeyboardInterrupt(f"signal {signum}")


@contextlib.contextmanager
def worker_pool(
    jobs: int, context: BaseContext, *, label: str = "a worker process"
) -> Iterator[ProcessPoolExecutor]:
    """A ProcessPoolExecutor of `jobs` workers, terminated at once if the block fails.

    A worker dying under the pool raises `WorkerDiedError` ("`label` died (how)").
    """
    main = threading.current_thread() is threading.main_thread()
    # Workers are forked with SIGINT/SIGTERM blocked, so a signal arriving before a
    # worker's initializer has set its handlers stays pending there instead of raising
    # KeyboardInterrupt in it; the parent gets it as soon as its mask is restored.
    previous_mask = signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS)
    previous_term = signal.getsignal(signal.SIGTERM) if main else None
    pool = ProcessPoolExecutor(
        max_workers=jobs, mp_context=context, initializer=_init_worker, initargs=(os.getpid(),)
    )
    try:
        pool.submit(os.getpid)  # starts the workers now, while the signals are blocked
        # Forked workers are all started by that first submit; the pool forgets them once
        # it breaks, so keep them to read how one died.
        workers = list((getattr(pool, "_processes", None) or {}).values())
        if main:
            signal.signal(signal.SIGTERM, _raise_interrupt)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous_mask)
    clean = False
    try:
        yield pool
        clean = True
    except BrokenProcessPool as exc:
        workers += (getattr(pool, "_processes", None) or {}).values()  # spawned later
        how, code = death_cause(workers)
        raise WorkerDiedError(f"{label} died ({how})", exit_code=code) from exc
    finally:
        if main:
            signal.signal(signal.SIGTERM, previous_term)
        if clean:
            pool.shutdown(wait=True)
        else:
            _terminate(pool)


def _terminate(pool: ProcessPoolExecutor) -> None:
    """Kill the pool's workers and drop its queued work without waiting for anything."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    for process in processes:
        with contextlib.suppress(Exception):
            process.terminate()
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        with contextlib.suppress(Exception):
            process.join(timeout=1.0)


def death_cause(workers: Iterable[BaseProcess]) -> tuple[str, int]:
    """How a pool's dead worker died, as a few words, and the exit code that fits.

    When one worker dies the pool SIGTERMs the others, so a worker that died any other
    way is the one to report. Killed by a signal from outside (the OOM killer's SIGKILL,
    `kill`): the run was interrupted, exit 130. Crashed (SIGSEGV and kin, an exit
    status): a bug, exit 70.
    """
    codes = [code for worker in dict.fromkeys(workers) if (code := _exit_code(worker)) is not None]
    if not codes:
        return "no exit status found", EXIT_INTERNAL
    code = min(codes, key=_telling)
    if code == 0:
        return "it exited normally mid-run", EXIT_INTERNAL
    if code > 0:
        return f"exited with status {code}", EXIT_INTERNAL
    number = -code
    try:
        name = signal.Signals(number).name
    except ValueError:
        name = "an unknown signal"
    if number in _CRASH_SIGNALS:
        return f"crashed with signal {number}, {name}: a bug, please report it", EXIT_INTERNAL
    if number == signal.SIGKILL:
        return (
            f"killed by signal {number} — out of memory? fewer jobs or more free memory may help",
            EXIT_INTERRUPTED,
        )
    return f"killed by signal {number}, {name}", EXIT_INTERRUPTED


def _exit_code(worker: BaseProcess) -> int | None:
    """A dead worker's exit status, or None if none came within `_REAP_S`.

    The pool's own thread reaps its dead workers too: when it wins the `waitpid`, our join
    returns at once with no status until that thread has stored it, so keep asking.
    """
    deadline = time.monotonic() + _REAP_S
    while True:
        with contextlib.suppress(Exception):
            worker.join(timeout=max(0.0, deadline - time.monotonic()))
            if worker.exitcode is not None:
                return worker.exitcode
        if time.monotonic() >= deadline:
            return None
        time.sleep(_REAP_POLL_S)


def _telling(exitcode: int) -> int:
    """Rank of a worker's exit status as the cause: a kill or a crash first, then an exit
    status, then the SIGTERM the pool itself sends the others, then a normal exit."""
    if exitcode < 0:
        return 2 if exitcode == -signal.SIGTERM else 0
    return 1 if exitcode > 0 else 3
