"""The parent's one-off work overlaps the workers' reading (issue 13's fixed cost).

Importing the audit does not import pandas (~0.2 s): the analysis is imported while the
reader workers run their first tasks (`iter_items(meanwhile=...)`), or before a serial
read, never both and never twice.
"""

from __future__ import annotations

import gc
import multiprocessing
import subprocess
import sys
from pathlib import Path

import pytest

from syncaudit.audit.plan import Item, read_plan
from syncaudit.logs import open_log
from syncaudit.logs import parallel as parallel_read
from syncaudit.rig import load_rig

REPO = Path(__file__).resolve().parents[2]
LOG = REPO / "sample_logs" / "pandar40p_adaptive.mcap"
"""Seven zstd chunks."""


def _items(jobs: int, calls: list[int]) -> list[Item]:
    rig = load_rig(Path(f"{LOG}.rig.yaml"))

    def meanwhile() -> None:
        calls.append(len(multiprocessing.active_children()))

    with open_log(LOG) as log:
        plan, _ = read_plan(log, rig, list(rig.cameras))
        return list(parallel_read.iter_items(log, plan, jobs, meanwhile=meanwhile))


def test_meanwhile_runs_once_while_the_workers_read(monkeypatch: pytest.MonkeyPatch) -> None:
    """Parallel path: called once, with the pool's two workers alive."""
    monkeypatch.setattr(parallel_read, "GROUP_BYTES", 1)  # a task per chunk: seven tasks
    calls: list[int] = []
    items = _items(2, calls)
    assert calls == [2]
    assert len(items) > 100


def test_meanwhile_runs_once_before_a_serial_read() -> None:
    """Serial path (one group, or jobs=1): called once, no worker process."""
    for jobs in (1, 2):
        calls: list[int] = []
        items = _items(jobs, calls)
        assert calls == [0]
        assert len(items) > 100


def test_importing_the_audit_does_not_import_pandas_or_rosbags() -> None:
    """The library API is importable without the analysis' pandas or rosbags' type system
    (imported where first needed)."""
    code = (
        "import sys, syncaudit.audit.run, syncaudit.logs.parallel\n"
        "from syncaudit.audit.run import audit_log, AuditResult\n"
        "print(sorted(m for m in ('pandas', 'rosbags.typesys') if m in sys.modules))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO
    )
    assert done.stdout.strip() == "[]"


_extract_group = parallel_read._extract_group


def _token_only(task: object, units: list[object]) -> list[parallel_read.Keyed]:
    """A worker task that fails unless the task came as its token (forked workers)."""
    if not isinstance(task, str) or task not in parallel_read._INHERITED_TASKS:
        raise AssertionError(f"task sent as {type(task).__name__}, not a known token")
    return _extract_group(task, units)  # type: ignore[arg-type]


@pytest.mark.skipif(
    "fork" not in multiprocessing.get_all_start_methods(), reason="forked workers only"
)
def test_forked_workers_get_the_task_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """Forked workers look the task up by token rather than unpickling it per group; the
    items are the serial path's, and the parent forgets the task when the pool ends."""
    serial = _items(1, [])
    monkeypatch.setattr(parallel_read, "GROUP_BYTES", 1)  # a task per chunk: seven tasks
    monkeypatch.setattr(parallel_read, "_extract_group", _token_only)
    parallel = _items(2, [])
    assert repr(parallel) == repr(serial)
    assert parallel_read._INHERITED_TASKS == {}


@pytest.mark.parametrize(("jobs", "caller_froze"), [(2, False), (2, True), (1, False)])
def test_what_the_read_made_is_no_young_pass_work(jobs: int, caller_froze: bool) -> None:
    """After the read the collector's young generation is (nearly) empty: what the read
    made went to the oldest generation, or to the caller's frozen heap (the CLI's)."""
    rig = load_rig(Path(f"{LOG}.rig.yaml"))
    try:
        if caller_froze:  # as the CLI does once its imports are done
            gc.freeze()
        with open_log(LOG) as log:
            plan, _ = read_plan(log, rig, list(rig.cameras))
            items = list(parallel_read.iter_items(log, plan, jobs))
            young = gc.get_count()[0]  # objects made since the read's end
        frozen = gc.get_freeze_count()
    finally:
        if caller_froze:
            gc.unfreeze()
    assert len(items) > 100
    assert young < 50
    assert (frozen > len(items)) is caller_froze


def test_no_garbage_collection_while_a_log_is_read() -> None:
    """The collector is paused while items stream (parallel or serial) and on again after,
    also when the caller stops early; a caller's own disabled collector stays disabled."""
    import gc
    import types

    rig = load_rig(Path(f"{LOG}.rig.yaml"))
    with open_log(LOG) as log:
        plan, _ = read_plan(log, rig, list(rig.cameras))
        for jobs in (1, 2):
            states = [gc.isenabled() for _ in parallel_read.iter_items(log, plan, jobs)]
            assert states and not any(states)
            assert gc.isenabled()
        items = parallel_read.iter_items(log, plan, 2)
        assert isinstance(items, types.GeneratorType)
        next(items)
        assert not gc.isenabled()
        items.close()
        assert gc.isenabled()
        gc.disable()
        try:
            assert len(list(parallel_read.iter_items(log, plan, 1))) > 100
            assert not gc.isenabled()
        finally:
            gc.enable()
