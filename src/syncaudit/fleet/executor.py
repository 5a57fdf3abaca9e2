"""Executors run log jobs somewhere and hand back one `LogOutcome` per job.

`Executor` is the protocol the driver uses; `LocalExecutor` is one long-lived worker
process per core (forked after the audit's imports, so interpreter start-up and imports
are paid once per worker, not per log). A worker that dies costs a retry of its log,
then an error row after `max_tries`; a log past `timeout_s` gets its worker killed and
a timeout error row. Another engine (Dask distributed for `--cluster`) implements the
same protocol: `run(jobs)` yields outcomes as they finish; the driver alone writes.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from typing import Any, Protocol

from syncaudit.fleet.inputs import LogJob
from syncaudit.fleet.job import JobOptions, LogOutcome, apply_test_hooks, run_log_job
from syncaudit.workers import die_with_parent

Task = Callable[[LogJob, JobOptions], LogOutcome]
DEFAULT_TIMEOUT_S = 3600.0
"""Per log: generous (a 2 GB log audits in ~2 s here; calibration takes minutes)."""
DEFAULT_MAX_TRIES = 2


class Executor(Protocol):
    """Runs log jobs and yields one outcome per job, in completion order."""

    def run(self, jobs: Iterable[LogJob], options: JobOptions) -> Iterator[LogOutcome]:
        """Yield exactly one outcome per job (an error outcome when it could not run)."""
        ...

    def close(self) -> None:
        """Release workers (idempotent)."""
        ...


def preload() -> None:
    """Import what every audit needs, once, before workers are forked."""
    import syncaudit.analysis.replay
    import syncaudit.analysis.sync
    import syncaudit.audit.run
    import syncaudit.report.html  # noqa: F401


def _worker_main(conn: Connection, task: Task, options: JobOptions, driver_pid: int) -> None:
    """Worker loop: receive a job, send its outcome; None ends the loop."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the driver decides about interrupts
    # Started with SIGINT blocked (see `_spawn`): a Ctrl-C that reached it before the line
    # above stayed pending, and is discarded now that it is ignored.
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    # A driver killed outright must not leave its workers auditing (or hanging) on.
    die_with_parent(driver_pid)
    os.setpgid(0, 0)  # its own group: killing it also kills the chunk processes it starts
    while True:
        try:
            job = conn.recv()
        except EOFError:
            return
        if job is None:
            return
        apply_test_hooks(job.path)
        conn.send(task(job, options))


@dataclass(slots=True)
class _Worker:
    process: Any
    conn: Connection
    job: LogJob | None = None
    attempt: int = 1
    started: float = 0.0


class LocalExecutor:
    """One worker process per core on this machine, each auditing whole logs."""

    def __init__(
        self,
        workers: int,
        *,
        timeout_s: float = DEFAULT_TIMEOUT_S,
        max_tries: int = DEFAULT_MAX_TRIES,
        task: Task = run_log_job,
        fresh_workers: bool = False,
    ) -> None:
        """`fresh_workers`: start each worker as a new interpreter (spawn), not a fork.

        Calibration runs OpenMP (small_gicp): a worker forked from a process whose
        OpenMP runtime already ran (a program that calibrated before calling `run_gate`)
        deadlocks in its first parallel region. A fresh worker pays the imports once.
        """
        self.workers = max(1, workers)
        self.timeout_s = timeout_s
        self.max_tries = max(1, max_tries)
        self.task = task
        self.fresh_workers = fresh_workers
        methods = multiprocessing.get_all_start_methods()
        forked = "fork" in methods and not fresh_workers
        self._context: Any = multiprocessing.get_context("fork" if forked else "spawn")
        self._pool: list[_Worker] = []

    def _spawn(self, options: JobOptions) -> _Worker:
        parent, child = self._context.Pipe()
        # Not a daemon: a worker may start its own chunk pool (few logs, many cores).
        process = self._context.Process(
            target=_worker_main, args=(child, self.task, options, os.getpid()), daemon=False
        )
        # A Ctrl-C reaches the whole process group: one arriving while a worker starts,
        # before it ignores SIGINT, would end it with a KeyboardInterrupt traceback. The
        # worker inherits the blocked mask (across fork and exec) and unblocks it itself.
        previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            process.start()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, previous)
        child.close()
        return _Worker(process, parent)

    def run(self, jobs: Iterable[LogJob], options: JobOptions) -> Iterator[LogOutcome]:
        """Run every job; dead workers are replaced, their log retried then given up."""
        queue: deque[tuple[LogJob, int]] = deque((job, 1) for job in jobs)
        if not queue:
            return
        if not self.fresh_workers:
            preload()  # once here, inherited by every forked worker
        wanted = min(self.workers, len(queue))
        self._pool = [self._spawn(options) for _ in range(wanted)]
        try:
            while queue or any(w.job is not None for w in self._pool):
                for worker in self._pool:
                    self._feed(worker, queue)
                busy = [w for w in self._pool if w.job is not None]
                deadline = min(w.started for w in busy) + self.timeout_s
                ready = wait(
                    [w.conn for w in busy] + [w.process.sentinel for w in busy],
                    timeout=max(0.0, deadline - time.monotonic()),
                )
                for index, worker in enumerate(list(self._pool)):
                    if worker.job is None:
                        continue
                    job, attempt = worker.job, worker.attempt
                    if worker.conn in ready:
                        try:
                            outcome: LogOutcome = worker.conn.recv()
                        except (EOFError, OSError):
                            outcome = None  # type: ignore[assignment]
                        if outcome is not None:
                            outcome.attempts = attempt
                            worker.job = None
                            # Next log first: the worker audits while the caller judges.
                            self._feed(worker, queue)
                            yield outcome
                            continue
                    if worker.process.sentinel in ready or worker.conn in ready:
                        code = worker.process.exitcode
                        self._replace(index, options)
                        if attempt < self.max_tries:
                            queue.appendleft((job, attempt + 1))
                        else:
                            yield LogOutcome(
                                job=job,
                                error=f"the worker died auditing this log ({attempt} tries; "
                                f"last exit code {code})",
                                error_code=3,
                                attempts=attempt,
                            )
                        continue
                    elapsed = time.monotonic() - worker.started
                    if elapsed >= self.timeout_s:
                        self._replace(index, options)
                        yield LogOutcome(
                            job=job,
                            error=f"timed out after {self.timeout_s:g} s (--timeout)",
                            error_code=3,
                            attempts=attempt,
                            elapsed_s=elapsed,
                        )
        finally:
            self.close()

    @staticmethod
    def _feed(worker: _Worker, queue: deque[tuple[LogJob, int]]) -> None:
        """Give an idle worker the next log, if any."""
        if worker.job is None and queue:
            job, attempt = queue.popleft()
            worker.job, worker.started, worker.attempt = job, time.monotonic(), attempt
            worker.conn.send(job)

    def _replace(self, index: int, options: JobOptions) -> None:
        """Kill a worker (dead or hung) and start a fresh one in its place."""
        old = self._pool[index]
        _kill(old)
        self._pool[index] = self._spawn(options)

    def close(self) -> None:
        """Stop every worker: a polite end of loop, then a kill for any that lingers."""
        for worker in self._pool:
            try:
                if worker.job is None:
                    worker.conn.send(None)
            except OSError:
                pass
        for worker in self._pool:
            if worker.job is None:
                worker.process.join(timeout=5)
            _kill(worker)
        self._pool = []


def _kill(worker: _Worker) -> None:
    """Kill a worker and the chunk processes it may have started, then reap it."""
    process = worker.process
    if process.is_alive():
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(process.pid, signal.SIGKILL)
        with contextlib.suppress(ProcessLookupError):
            os.kill(process.pid, signal.SIGKILL)
    process.join(timeout=5)
    worker.conn.close()


class SerialExecutor:
    """Audits in this process, one log after another (`--jobs 1`; no crash isolation)."""

    def __init__(self, task: Task = run_log_job) -> None:
        self.task = task

    def run(self, jobs: Iterable[LogJob], options: JobOptions) -> Iterator[LogOutcome]:
        """Run each job here."""
        for job in jobs:
            yield self.task(job, options)

    def close(self) -> None:
        """Nothing to release."""
