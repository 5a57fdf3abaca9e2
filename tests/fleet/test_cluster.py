"""`syncaudit gate --cluster`: the sample logs audited on a real local Dask cluster.

The cluster is a scheduler and two nanny-supervised worker processes talking TCP on
loopback, as `dask scheduler` + `dask worker` would run them; the tests kill worker
processes for real and check what the driver records.
"""

from __future__ import annotations

import os
import re
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from syncaudit.fleet.gate import GateOptions, run_gate
from syncaudit.fleet.policy import parse_policy

from .conftest import SAMPLES

distributed = pytest.importorskip("distributed")
dask = pytest.importorskip("dask")

POLICY = {
    "vehicle_pattern": r"uploads/(?P<vehicle>[^/]+)/",
    "defaults": {
        "camera": {"error_mean_us": {"max": 2500}, "error_var_us2": {"max": 1e7}},
        "lidar": {"rpm": {"min": 500, "max": 700}},
    },
    "vehicles": {"car1": {"cameras": {"front": {"error_mean_us": {"max": 1000}}}}},
}
ALLOWED_FAILURES = 1
"""The test scheduler gives a log whose worker died one more try (Dask's default is 3)."""
WORKERS = 2
WORKER_START_S = 240.0
"""How long a worker process may take to (re)start: its nanny spawns a new interpreter that
imports distributed and syncaudit, seconds when idle but beyond 30 s on a loaded 2-core CI
machine (load ~10). Only the waits for workers to start use it; the waits return as soon as
the workers are up, and the timeouts the tests are about keep their own short bounds."""


@pytest.fixture(scope="module")
def hooks(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder for the slow-log hook's PID file."""
    return tmp_path_factory.mktemp("cluster-hooks")


@pytest.fixture(scope="module")
def cluster(hooks: Path) -> Iterator[str]:
    """A scheduler and two single-threaded worker processes on 127.0.0.1 (TCP)."""
    from distributed import LocalCluster

    saved = dict(os.environ)
    # Read by the workers (spawned now, and respawned by their nannies after a kill).
    os.environ["SYNCAUDIT_FLEET_TEST_CRASH"] = "crashme"
    os.environ["SYNCAUDIT_FLEET_TEST_HANG"] = "hangme"
    os.environ["SYNCAUDIT_FLEET_TEST_SLOW"] = f"slowme:{hooks / 'slow.pid'}"
    settings = {
        "distributed.scheduler.allowed-failures": ALLOWED_FAILURES,
        # One log per worker thread at a time: a log queued behind a dying one is not
        # charged with its deaths (Dask's default 1.1 sends two per 1-thread worker).
        "distributed.scheduler.worker-saturation": 1.0,
        # LocalCluster closes the nanny of a worker that is not back this long after it
        # left (default 15 s): under load a restart takes longer, and the cluster would
        # keep one worker for good. Read when a worker leaves: set for the module's life.
        "distributed.deploy.lost-worker-timeout": f"{WORKER_START_S}s",
    }
    with dask.config.set(settings):
        local = LocalCluster(
            processes=True,
            n_workers=WORKERS,
            threads_per_worker=1,
            host="127.0.0.1",
            dashboard_address=":0",
            protocol="tcp",
        )
        try:
            assert local.scheduler_address.startswith("tcp://127.0.0.1:")
            yield local.scheduler_address
        finally:
            local.close()
            os.environ.clear()
            os.environ.update(saved)


def _wait_for_workers(address: str) -> None:
    """Until the scheduler counts both workers running (`WORKER_START_S` at the most)."""
    from distributed import Client

    with Client(address, set_as_default=False, timeout=WORKER_START_S) as client:
        client.wait_for_workers(WORKERS, timeout=WORKER_START_S)


@pytest.fixture()
def whole(cluster: str) -> str:
    """The cluster with both workers up (a previous test may have had one restarted)."""
    _wait_for_workers(cluster)
    return cluster


def _fleet(root: Path, logs: dict[str, str]) -> Path:
    """uploads/<vehicle>/<name> symlinks to sample logs (and their rigs)."""
    for target, sample in logs.items():
        path = root / "uploads" / target
        path.parent.mkdir(parents=True, exist_ok=True)
        path.symlink_to(SAMPLES / sample)
        Path(f"{path}.rig.yaml").symlink_to(SAMPLES / f"{sample}.rig.yaml")
    return root / "uploads"


def _rows(db: Path, table: str) -> list[tuple[Any, ...]]:
    """A table's rows, without the columns that hold wall-clock times."""
    import duckdb

    with duckdb.connect(str(db), read_only=True) as con:
        columns = [
            c[0]
            for c in con.execute(f"DESCRIBE SELECT * FROM {table}").fetchall()
            if c[0] not in {"elapsed_s", "judged_at"}
        ]
        query = f"SELECT {', '.join(columns)} FROM {table} ORDER BY ALL"
        return con.execute(query).fetchall()


def test_cluster_run_writes_what_a_local_run_writes(whole: str, tmp_path: Path) -> None:
    uploads = _fleet(
        tmp_path,
        {
            "car1/vlp16_three_cameras.mcap": "vlp16_three_cameras.mcap",
            "car2/pandar40p_adaptive.mcap": "pandar40p_adaptive.mcap",
            "car2/vlp16_short.bag": "vlp16_short.bag",
        },
    )
    policy = parse_policy(POLICY, "policy.yaml")
    outputs = {}
    for name, address in (("local", None), ("cluster", whole)):
        out = tmp_path / name
        out.mkdir()
        options = GateOptions(
            db=out / "fleet.duckdb",
            json_out=out / "gate.json",
            junit=out / "gate.xml",
            summary=out / "gate.md",
            jobs=2,
            cluster=address,
        )
        run = run_gate([str(uploads)], policy, options)
        assert run.exit_code == 10  # car1's front camera is over its 1000 us limit
        assert [log.verdict for log in run.logs] == ["fail", "warn", "pass"]
        outputs[name] = out
    for name in ("gate.json", "gate.md"):
        local = (outputs["local"] / name).read_bytes()
        assert local == (outputs["cluster"] / name).read_bytes(), name
    # JUnit carries each log's audit time; everything else is the same.
    untimed = [
        re.sub(rb'time="[0-9.]+"', b"", (outputs[name] / "gate.xml").read_bytes())
        for name in ("local", "cluster")
    ]
    assert untimed[0] == untimed[1]
    for table, count in (("logs", 3), ("cameras", 9)):
        local_rows = _rows(outputs["local"] / "fleet.duckdb", table)
        assert len(local_rows) == count, table
        assert local_rows == _rows(outputs["cluster"] / "fleet.duckdb", table), table


def test_killed_worker_costs_a_retry_not_the_run(whole: str, hooks: Path, tmp_path: Path) -> None:
    uploads = _fleet(
        tmp_path,
        {
            "car1/slowme.mcap": "vlp16_three_cameras.mcap",
            "car2/pandar40p_adaptive.mcap": "pandar40p_adaptive.mcap",
        },
    )
    pid_file = hooks / "slow.pid"
    killed: list[int] = []
    finished = threading.Event()

    def killer() -> None:
        # The first try writes the file once its worker has the task: under load the
        # worker's first import of syncaudit alone can take tens of seconds.
        deadline = time.monotonic() + WORKER_START_S
        while not pid_file.exists() and time.monotonic() < deadline:
            if finished.wait(0.05):
                return
        if pid_file.exists():
            pid = int(pid_file.read_text())
            os.kill(pid, signal.SIGKILL)  # the worker process auditing slowme.mcap
            killed.append(pid)

    thread = threading.Thread(target=killer, daemon=True)
    thread.start()
    # The timeout only bounds a test whose kill went wrong; each try has its own clock.
    options = GateOptions(db=None, cluster=whole, timeout_s=WORKER_START_S)
    try:
        run = run_gate([str(uploads)], parse_policy(POLICY, "policy.yaml"), options)
    finally:
        finished.set()
        thread.join(timeout=WORKER_START_S)
    assert killed, "the slow log never started"
    by_name = {Path(log.path).name: log for log in run.logs}
    slow = by_name["slowme.mcap"]
    assert slow.error is None and slow.verdict == "fail"  # audited on the retry
    assert slow.attempts == 2
    assert by_name["pandar40p_adaptive.mcap"].attempts == 1
    assert by_name["pandar40p_adaptive.mcap"].verdict == "warn"


def test_log_that_kills_workers_becomes_an_error_row(whole: str, tmp_path: Path) -> None:
    uploads = _fleet(
        tmp_path,
        {
            "car1/crashme.mcap": "vlp16_three_cameras.mcap",
            "car2/pandar40p_adaptive.mcap": "pandar40p_adaptive.mcap",
        },
    )
    out = tmp_path / "gate.json"
    run = run_gate(
        [str(uploads)],
        parse_policy(POLICY, "policy.yaml"),
        GateOptions(db=None, json_out=out, cluster=whole),
    )
    assert run.exit_code == 3
    by_name = {Path(log.path).name: log for log in run.logs}
    crash = by_name["crashme.mcap"]
    assert crash.verdict == "error" and crash.error_code == 3
    assert crash.attempts == ALLOWED_FAILURES + 1
    assert crash.error is not None and "KilledWorker" in crash.error
    assert by_name["pandar40p_adaptive.mcap"].verdict == "warn"


def test_per_log_timeout_on_the_cluster(whole: str, tmp_path: Path) -> None:
    # The hung log alone: under load a real audit can outlast a short timeout too.
    uploads = _fleet(tmp_path, {"car1/hangme.mcap": "vlp16_three_cameras.mcap"})
    started = time.monotonic()
    run = run_gate(
        [str(uploads)],
        parse_policy(POLICY, "policy.yaml"),
        GateOptions(db=None, cluster=whole, timeout_s=3),
    )
    assert time.monotonic() - started < 300  # far below the hook's 3600 s sleep, even loaded
    (hung,) = run.logs
    assert hung.verdict == "error" and hung.error is not None and "timed out" in hung.error
    assert run.exit_code == 3
    # The hung worker was restarted: the cluster has two workers to audit with again (its
    # nanny's new process may start slowly on a loaded machine: a start-up bound).
    _wait_for_workers(whole)


def test_unreachable_scheduler_is_a_usage_error() -> None:
    from syncaudit.errors import UsageError
    from syncaudit.fleet.dask_executor import DaskExecutor

    with pytest.raises(UsageError, match="cannot reach the scheduler") as caught:
        DaskExecutor("tcp://127.0.0.1:9", connect_timeout_s=1)
    assert caught.value.exit_code == 64


class _Scripted:
    """What the scheduler says runs where, as `Client.processing()` answers, per poll."""

    def __init__(self) -> None:
        self.running: dict[str, list[str]] = {}
        self.restarted: list[str] = []

    def processing(self) -> dict[str, list[str]]:
        return self.running

    def restart_workers(self, workers: list[str], *, raise_for_error: bool) -> None:
        self.restarted += workers


class _Future:
    key = "audit-slowme"

    def cancel(self) -> None:
        pass


def test_each_try_on_the_cluster_has_its_own_clock(monkeypatch: pytest.MonkeyPatch) -> None:
    """A retry after a worker died is timed from its own start, as local tries are: the
    time the dead worker spent and the wait for a new worker are not charged to it (under
    load a restart takes tens of seconds; the killed-worker test then timed out)."""
    from syncaudit.fleet import dask_executor
    from syncaudit.fleet.dask_executor import DaskExecutor
    from syncaudit.fleet.inputs import LogJob

    executor = DaskExecutor.__new__(DaskExecutor)  # no scheduler: the clock logic alone
    client = _Scripted()
    executor._client, executor.timeout_s = client, 10.0
    future, job = _Future(), LogJob(path="car1/slowme.mcap", vehicle="car1")
    futures: dict[Any, LogJob] = {future: job}
    started: dict[Any, tuple[str, float]] = {}
    now = [0.0]
    monkeypatch.setattr(dask_executor.time, "monotonic", lambda: now[0])

    def poll(at_s: float, worker: str | None) -> list[Any]:
        now[0] = at_s
        client.running = {worker: [future.key]} if worker else {}
        return list(executor._expire(futures, started))

    assert poll(0.0, "tcp://127.0.0.1:1001") == []  # first try
    assert poll(8.0, None) == []  # its worker was killed: waiting for a retry
    assert poll(9.0, "tcp://127.0.0.1:1002") == []  # the retry starts its clock
    assert poll(18.5, "tcp://127.0.0.1:1002") == []  # 9.5 s into the retry (18.5 in all)
    (timed_out,) = poll(19.5, "tcp://127.0.0.1:1002")  # 10.5 s into the retry
    assert timed_out.job is job and timed_out.elapsed_s == pytest.approx(10.5)
    assert "timed out after 10 s" in (timed_out.error or "")
    assert client.restarted == ["tcp://127.0.0.1:1002"] and futures == {} and started == {}
    # A retry landing straight on another worker (no poll in between) is a new try too.
    futures[future] = job
    assert poll(30.0, "tcp://127.0.0.1:1003") == []
    assert poll(39.0, "tcp://127.0.0.1:1004") == []
    assert poll(48.0, "tcp://127.0.0.1:1004") == []
    assert len(poll(49.0, "tcp://127.0.0.1:1004")) == 1
