"""`DaskExecutor`: the gate's per-log audits on an existing Dask distributed cluster.

The driver submits one task per log to the cluster's scheduler (`tcp://host:8786`) and
takes the outcomes back as they finish; it alone writes the database and the outputs,
so a cluster run writes what a local run writes. Nothing here schedules, queues or
talks to workers itself: Dask does.

Worker loss is Dask's: when a worker dies while auditing a log, the scheduler gives the
log to another worker and counts the death on the task (`suspicious`); past the
scheduler's `distributed.scheduler.allowed-failures` (default 3) the task fails with
`KilledWorker`, which becomes the log's error row (exit 3). The tries a log took are
read back from the scheduler. A try past `timeout_s` is cancelled, its worker restarted
by its nanny (a Python thread cannot be stopped otherwise), and a timeout row recorded;
as in a local run, each try has its own clock (a retry after a worker died does not
inherit the time the dead worker spent, nor the time the log waited to be retried).
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterable, Iterator
from dataclasses import replace
from typing import Any

from syncaudit.errors import UsageError
from syncaudit.fleet.executor import DEFAULT_TIMEOUT_S, Task
from syncaudit.fleet.inputs import LogJob
from syncaudit.fleet.job import JobOptions, LogOutcome, apply_test_hooks, run_log_job

POLL_S = 0.5
"""How often the driver looks for logs past their timeout while waiting for results."""


def cluster_task(job: LogJob, options: JobOptions, task: Task = run_log_job) -> LogOutcome:
    """What a cluster worker runs for one log: the test hooks, then the audit."""
    apply_test_hooks(job.path)
    _slow_hook(job.path)
    return task(job, options)


def _slow_hook(path: str) -> None:
    """Test hook: SYNCAUDIT_FLEET_TEST_SLOW=<substring>:<pid file> stalls the first try.

    The worker auditing a matching log writes its PID to the file and sleeps, so a
    test can kill exactly that worker mid-audit; a later try (the file exists) goes on.
    """
    spec = os.environ.get("SYNCAUDIT_FLEET_TEST_SLOW")
    if not spec or ":" not in spec:
        return
    marker, pid_file = spec.split(":", 1)
    if marker not in path or os.path.exists(pid_file):
        return
    with open(pid_file + ".tmp", "w") as handle:
        handle.write(str(os.getpid()))
    os.replace(pid_file + ".tmp", pid_file)
    time.sleep(60)


def _absolute(job: LogJob) -> LogJob:
    """The job with absolute local paths: workers do not share the driver's directory."""
    if "://" in job.path:
        return job
    rig = job.rig_path
    rig = os.path.abspath(rig) if rig and "://" not in rig else rig
    return replace(job, path=os.path.abspath(job.path), rig_path=rig)


def _deaths_on_scheduler(dask_scheduler: Any, keys: list[str]) -> dict[str, int]:
    """Run on the scheduler: how many workers died while running each task."""
    deaths = {}
    for key in keys:
        state = dask_scheduler.tasks.get(key)
        deaths[key] = state.suspicious if state is not None else 0
    return deaths


class DaskExecutor:
    """Runs each log's audit as one task on a Dask distributed cluster."""

    def __init__(
        self,
        address: str,
        *,
        timeout_s: float = DEFAULT_TIMEOUT_S,
        task: Task = run_log_job,
        connect_timeout_s: float = 10.0,
    ) -> None:
        try:
            from distributed import Client
        except ImportError:
            raise UsageError(
                "--cluster needs Dask distributed: pip install 'syncaudit[cluster]'"
            ) from None
        self.address = address
        self.timeout_s = timeout_s
        self.task = task
        try:
            connect: Any = Client  # untyped in distributed
            self._client: Any = connect(address, timeout=connect_timeout_s, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise UsageError(f"--cluster {address}: cannot reach the scheduler ({exc})") from None

    def run(self, jobs: Iterable[LogJob], options: JobOptions) -> Iterator[LogOutcome]:
        """Submit every job, yield outcomes as they complete (timeouts and deaths as rows)."""
        from distributed import wait

        def wait_any(pending: list[Any], *, timeout: float) -> Any:
            call: Any = wait  # untyped in distributed
            return call(pending, timeout=timeout, return_when="FIRST_COMPLETED")

        from distributed.client import FutureCancelledError

        # Worker processes are daemonic (no chunk pools of their own): one reader per log.
        options = JobOptions(
            audit_jobs=1, calibrate=options.calibrate, html=options.html, policy=options.policy
        )
        futures: dict[Any, LogJob] = {}
        for job in jobs:
            future = self._client.submit(
                cluster_task, _absolute(job), options, self.task, pure=False
            )
            futures[future] = job
        started: dict[Any, tuple[str, float]] = {}
        try:
            while futures:
                try:
                    with self._client.as_current():
                        waited = wait_any(list(futures), timeout=POLL_S)
                    done = waited.done
                except TimeoutError:
                    done = set()
                for future in done:
                    yield self._outcome(future, futures.pop(future), FutureCancelledError)
                yield from self._expire(futures, started)
        finally:
            for future in futures:
                future.cancel()

    def _outcome(self, future: Any, job: LogJob, cancelled: type[BaseException]) -> LogOutcome:
        """The outcome of a finished future: the audit's, or an error row for a dead worker."""
        from distributed import KilledWorker

        try:
            deaths = self._client.run_on_scheduler(_deaths_on_scheduler, keys=[future.key])
            died = int(deaths.get(future.key, 0))
        except Exception:
            died = 0
        attempts = died + 1
        try:
            outcome: LogOutcome = future.result()
        except KilledWorker as exc:
            return LogOutcome(
                job=job,
                error=f"the cluster worker died auditing this log ({died} tries; Dask "
                f"KilledWorker, see distributed.scheduler.allowed-failures): {exc.args[0]}",
                error_code=3,
                attempts=max(1, died),
            )
        except cancelled:
            return LogOutcome(job=job, error="cancelled on the cluster", error_code=3)
        except Exception as exc:  # a task that could not run (e.g. unpicklable, env)
            return LogOutcome(
                job=job,
                error=f"cluster task failed: {type(exc).__name__}: {exc}".splitlines()[0],
                error_code=3,
                attempts=attempts,
            )
        finally:
            future.release()
        outcome.attempts = attempts
        outcome.job = job  # as the driver named it (relative paths stay relative)
        return outcome

    def _expire(
        self, futures: dict[Any, LogJob], started: dict[Any, tuple[str, float]]
    ) -> Iterator[LogOutcome]:
        """Time out tries running longer than `timeout_s`: cancel, restart their worker.

        `started` maps a future to the worker running its current try and when the driver
        first saw it there; a log no longer running (its worker died, it waits for a
        retry) or running on another worker is on a new try, with a new clock.
        """
        if not futures:
            return
        now = time.monotonic()
        processing = self._client.processing()
        running = {key: worker for worker, keys in processing.items() for key in keys}
        for future in list(futures):
            worker = running.get(future.key)
            if worker is None:
                started.pop(future, None)
                continue
            if future not in started or started[future][0] != worker:
                started[future] = (worker, now)
            since = started[future][1]
            if now - since < self.timeout_s:
                continue
            started.pop(future)
            job = futures.pop(future)
            future.cancel()
            with contextlib.suppress(Exception):
                self._client.restart_workers([worker], raise_for_error=False)
            yield LogOutcome(
                job=job,
                error=f"timed out after {self.timeout_s:g} s on cluster worker {worker} "
                "(--timeout); the worker was restarted",
                error_code=3,
                elapsed_s=now - since,
            )

    def close(self) -> None:
        """Disconnect from the scheduler (the cluster itself is left running)."""
        with contextlib.suppress(Exception):
            self._client.close()
