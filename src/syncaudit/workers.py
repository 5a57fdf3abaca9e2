"""A process pool that dies with its parent and turns any interruption into one clean exit.

Worker processes ignore SIGINT (a Ctrl-C reaches the whole process group: only the parent
acts on it, so no worker prints a traceback), take SIGTERM's default action, and on Linux
ask the kernel to kill them when their parent dies (PR_SET_PDEATHSIG), so a parent killed
outright leaves no orphan. While the pool runs, SIGTERM to the parent raises
KeyboardInterrupt like SIGINT does (the CLI exits 130 on either); the pool's workers are
then terminated at once, never waited for (a worker blocked on a pipe must not hang it).
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import sys
import threading
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from multiprocessing.context import BaseContext
from types import FrameType

_PR_SET_PDEATHSIG = 1
_STOP_SIGNALS = {signal.SIGINT, signal.SIGTERM}


def _init_worker(parent_pid: int) -> None:
    """Worker start: ignore Ctrl-C, die with the parent, then accept signals again."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):  # pragma: no cover - no prctl: best effort
            pass
    if os.getppid() != parent_pid:  # the parent died before the prctl took hold
        os._exit(1)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _STOP_SIGNALS)


def _raise_interrupt(signum: int, frame: FrameType | None) -> None:
    """SIGTERM in the parent while the pool runs: stop like Ctrl-C does."""
    raise KeyboardInterrupt(f"signal {signum}")


@contextlib.contextmanager
def worker_pool(jobs: int, context: BaseContext) -> Iterator[ProcessPoolExecutor]:
    """A ProcessPoolExecutor of `jobs` workers, terminated at once if the block fails."""
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
        if main:
            signal.signal(signal.SIGTERM, _raise_interrupt)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous_mask)
    clean = False
    try:
        yield pool
        clean = True
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
