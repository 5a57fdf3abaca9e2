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

from syncaudit import collect
from syncaudit.audit import _plan
from syncaudit.logs import open_log
from syncaudit.rig import load_rig

REPO = Path(__file__).resolve().parents[2]
LOG = REPO / "sample_logs" / "pandar40p_adaptive.mcap"
"""Seven zstd chunks."""


def _items(jobs: int, calls: list[int]) -> list[collect.Item]:
    rig = load_rig(Path(f"{LOG}.rig.yaml"))

    def meanwhile() -> None:
        calls.append(len(multiprocessing.active_children()))

    with open_log(LOG) as log:
        plan, _ = _plan(log, rig, list(rig.cameras))
        return list(collect.iter_items(log, plan, jobs, meanwhile=meanwhile))


def test_meanwhile_runs_once_while_the_workers_read(monkeypatch: pytest.MonkeyPatch) -> None:
    """Parallel path: called once, with the pool's two workers alive."""
    monkeypatch.setattr(collect, "GROUP_BYTES", 1)  # a task per chunk: seven tasks
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
        "import sys, syncaudit.audit, syncaudit.collect\n"
        "from syncaudit.audit import audit_log, AuditResult\n"
        "print(sorted(m for m in ('pandas', 'rosbags.typesys') if m in sys.modules))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO
    )
    assert done.stdout.strip() == "[]"


_extract_group = collect._extract_group


def _token_only(task: object, units: list[object]) -> list[collect.Keyed]:
    """A worker task that fails unless the task came as its token (forked workers)."""
    if not isinstance(task, str) or task not in collect._INHERITED_TASKS:
        raise AssertionError(f"task sent as {type(task).__name__}, not a known token")
    return _extract_group(task, units)  # type: ignore[arg-type]


@pytest.mark.skipif(
    "fork" not in multiprocessing.get_all_start_methods(), reason="forked workers only"
)
def test_forked_workers_get_the_task_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """Forked workers look the task up by token rather than unpickling it per group; the
    items are the serial path's, and the parent forgets the task when the pool ends."""
    serial = _items(1, [])
    monkeypatch.setattr(collect, "GROUP_BYTES", 1)  # a task per chunk: seven tasks
    monkeypatch.setattr(collect, "_extract_group", _token_only)
    parallel = _items(2, [])
    assert repr(parallel) == repr(serial)
    assert collect._INHERITED_TASKS == {}


@pytest.mark.parametrize(("enabled", "caller_froze"), [(True, False), (True, True), (False, False)])
def test_cycle_collector_paused_while_workers_read(
    monkeypatch: pytest.MonkeyPatch, enabled: bool, caller_froze: bool
) -> None:
    """The parent's collector is off while the pool runs, and as the caller had it after;
    what the read made is no young-generation pass's work."""
    monkeypatch.setattr(collect, "GROUP_BYTES", 1)
    rig = load_rig(Path(f"{LOG}.rig.yaml"))
    during: list[bool] = []
    was = gc.isenabled()
    try:
        gc.enable() if enabled else gc.disable()
        if caller_froze:  # as the CLI does once its imports are done
            gc.freeze()
        with open_log(LOG) as log:
            plan, _ = _plan(log, rig, list(rig.cameras))
            items = list(
                collect.iter_items(log, plan, 2, meanwhile=lambda: during.append(gc.isenabled()))
            )
            young = gc.get_count()[0]  # objects made since the read's end (or a pass)
        after = gc.isenabled()
    finally:
        if caller_froze:
            gc.unfreeze()
        gc.enable() if was else gc.disable()
    assert during == [False]
    assert after is enabled
    if enabled:  # the read's rows were frozen with the heap, not left to young passes
        assert young < 50
    assert len(items) > 100
