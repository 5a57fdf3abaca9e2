"""A signed URL's query string reaches every worker, forked or spawned, and nothing else:
read units, task reprs, results and messages name the log without it."""

from __future__ import annotations

import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import pytest

from syncaudit.audit.run import audit_log
from syncaudit.logs import open_log
from syncaudit.logs import parallel as parallel_read
from syncaudit.logs.mcap import remote as mcap_remote
from syncaudit.logs.ros1 import remote as rosbag1_remote
from syncaudit.remote.file import signed_url
from syncaudit.rig import load_rig

from .conftest import ServerState, fetched

REPO = Path(__file__).resolve().parents[2]
SAMPLES = REPO / "sample_logs"
QUERY = "X-Amz-Credential=AKIA&X-Amz-Signature=s3cr3t"


def _without_path(result: Any) -> dict[str, Any]:
    data: dict[str, Any] = result.to_dict()
    data.pop("path", None)
    return data


@pytest.mark.parametrize("start_method", ["fork", "spawn"])
@pytest.mark.parametrize("name", ["vlp16_three_cameras.mcap", "vlp16_short.bag"])
def test_workers_read_a_signed_url_that_is_never_shown(
    http_root: tuple[str, ServerState],
    monkeypatch: pytest.MonkeyPatch,
    start_method: str,
    name: str,
) -> None:
    base, state = http_root
    (state.root / name).symlink_to(SAMPLES / name)
    state.required_query = QUERY  # the server refuses the URL without its signature
    monkeypatch.setattr(mcap_remote, "RANGE_BYTES", 600_000)  # several units, two workers
    monkeypatch.setattr(rosbag1_remote, "RANGE_BYTES", 1 << 20)
    monkeypatch.setattr(parallel_read, "GROUP_BYTES", 1)  # a task per unit: the parallel path
    monkeypatch.setattr(multiprocessing, "get_all_start_methods", lambda: [start_method])
    tasks: list[Any] = []
    submit = ProcessPoolExecutor.submit

    def spy(pool: ProcessPoolExecutor, fn: Any, /, *args: Any, **kwargs: Any) -> Any:
        if args and isinstance(args[0], parallel_read._Task):
            tasks.append(args)  # what travels to the reader workers: (task, units)
        elif args and isinstance(args[0], str):  # a forked worker's token of its task
            assert "s3cr3t" not in args[0]
            tasks.append((parallel_read._INHERITED_TASKS[args[0]], *args[1:]))
        return submit(pool, fn, *args, **kwargs)

    monkeypatch.setattr(ProcessPoolExecutor, "submit", spy)
    rig = load_rig(SAMPLES / f"{name}.rig.yaml")
    url = f"{base}/{name}?{QUERY}"
    with open_log(url) as log:
        units = log.read_units(frozenset(log.topics))
        assert units and all(u.source == f"{base}/{name}" for u in units)
        assert signed_url(f"{base}/{name}") == url  # while the log is open, in this process
    before = len(state.requests)
    with open_log(url) as log:  # its fetch statistics cover the audit's own open
        remote = audit_log(url, rig, jobs=2)
        stats = fetched(log)
    assert _without_path(remote) == _without_path(audit_log(SAMPLES / name, rig, jobs=2))
    assert "s3cr3t" not in repr(remote.to_dict()) and "s3cr3t" not in repr(stats)
    assert all(" bytes=" in r and "s3cr3t" in r for r in state.requests)  # all signed
    # The task carries the signed URL to spawned workers (forked ones inherit it), and
    # does not show it.
    tasks = [(task, units) for task, units in tasks if task.log_path == f"{base}/{name}"]
    assert tasks and all(task.open_as == url for task, _ in tasks)
    assert all("s3cr3t" not in repr(task) + repr(units) for task, units in tasks)
    got = state.requests[before:]
    if start_method == "spawn":  # each spawned worker fetched the index again
        assert len(got) > stats["requests"]
    else:
        assert len(got) == stats["requests"]
