"""Chunk-parallel extraction gives exactly the serial result (same items, same order)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from syncaudit.audit.plan import ExtractPlan, Item, read_plan
from syncaudit.audit.run import audit_log
from syncaudit.logs import open_log
from syncaudit.logs import parallel as parallel_read
from syncaudit.logs.ros2 import sqlite_rows
from syncaudit.simulate.rig_file import rig_from_truth
from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log


@pytest.fixture(scope="module")
def chunked_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, object]]:
    out = tmp_path_factory.mktemp("par") / "log.mcap"
    truth = simulate_sync_log(out, SyncSimConfig(seed=61, duration_s=4.0, lidar_model="Pandar40P"))
    return out, truth


def test_parallel_equals_serial(
    chunked_log: tuple[Path, dict[str, object]], monkeypatch: pytest.MonkeyPatch
) -> None:
    out, truth = chunked_log
    # Small groups: many tasks, merges across every group boundary.
    monkeypatch.setattr(parallel_read, "GROUP_BYTES", 200_000)
    rig = rig_from_truth(truth)  # type: ignore[arg-type]
    serial = audit_log(out, rig, jobs=1)
    parallel = audit_log(out, rig, jobs=2)
    assert json.dumps(serial.to_dict(), sort_keys=True) == json.dumps(
        parallel.to_dict(), sort_keys=True
    )
    assert serial.frames().equals(parallel.frames())


def test_parallel_items_in_log_order(
    chunked_log: tuple[Path, dict[str, object]], monkeypatch: pytest.MonkeyPatch
) -> None:
    out, truth = chunked_log
    monkeypatch.setattr(parallel_read, "GROUP_BYTES", 100_000)
    rig = rig_from_truth(truth)  # type: ignore[arg-type]
    with open_log(out) as log:
        refs = log.read_units(frozenset(_plan(log, rig).topics))
        assert refs is not None and len(refs) >= 3  # one group per chunk at this size
        serial = [(k, t) for k, t, _ in parallel_read.iter_items(log, _plan(log, rig), jobs=1)]
        parallel = [(k, t) for k, t, _ in parallel_read.iter_items(log, _plan(log, rig), jobs=2)]
    assert serial == parallel
    assert len(serial) > 100


def _plan(log: object, rig: object) -> ExtractPlan:
    plan, _ = read_plan(log, rig, list(rig.cameras))  # type: ignore[arg-type, attr-defined]
    return plan


def _comparable(item: Item) -> tuple[object, ...]:
    kind, topic, payload = item
    if kind == "lidar":
        fields = (getattr(payload, name) for name in payload.__slots__)
        return kind, topic, tuple(f.tolist() if hasattr(f, "tolist") else f for f in fields)
    return kind, topic, payload


@pytest.mark.parametrize("model", ["Pandar40P", "VLP-16"])
def test_chunk_items_equal_message_items(
    tmp_path: Path, model: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Items read chunk by chunk (buffers reused between chunks) own their data: they equal
    the items of a plain message-by-message read, serial and parallel."""
    out = tmp_path / "log.mcap"
    truth = simulate_sync_log(out, SyncSimConfig(seed=62, duration_s=5.0, lidar_model=model))
    rig = rig_from_truth(truth)  # type: ignore[arg-type]
    with open_log(out) as log:
        plan = _plan(log, rig)
        refs = log.read_units(frozenset(plan.topics))
        assert refs is not None and len(refs) >= 2  # the buffers are reused
        chunked = {
            jobs: [_comparable(i) for i in parallel_read.iter_items(log, plan, jobs=jobs)]
            for jobs in (1, 2)
        }
        monkeypatch.setattr(type(log), "read_units", lambda self, topics: None)
        plain = [_comparable(i) for i in parallel_read.iter_items(log, plan, jobs=1)]
    assert len(plain) > 100
    assert chunked[1] == plain
    assert chunked[2] == plain


def test_no_pool_for_a_log_of_one_group(
    chunked_log: tuple[Path, dict[str, object]], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A log that fits one task is read in the parent: starting workers would only cost."""
    out, truth = chunked_log
    rig = rig_from_truth(truth)  # type: ignore[arg-type]

    def no_pool(*_args: object) -> None:
        raise AssertionError("a pool was started for a log of one group")

    monkeypatch.setattr(parallel_read, "worker_pool", no_pool)
    with open_log(out) as log:
        plan = _plan(log, rig)
        units = log.read_units(frozenset(plan.topics))
        assert units is not None and len(units) > 1
        assert sum(u.cost for u in units) < parallel_read.GROUP_BYTES  # one group
        items = list(parallel_read.iter_items(log, plan, jobs=2))
    assert len(items) > 100


@pytest.mark.parametrize("cut", ["mid-chunk", "before-summary"])
def test_cut_log_read_in_parallel_equals_serial(
    chunked_log: tuple[Path, dict[str, object]],
    tmp_path: Path,
    cut: str,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A recording cut off (no summary): its chunks, found by the linear scan, are the read
    units, the partly written last one read up to the cut; the items equal the serial
    read's, with jobs 1 and 2."""
    out, truth = chunked_log
    monkeypatch.setattr(parallel_read, "GROUP_BYTES", 200_000)
    rig = rig_from_truth(truth)
    with open_log(out) as log:
        units = sorted(log.read_units(frozenset(log.topics)) or [], key=lambda u: u.offset)
    last = units[-1]
    end = last.offset + last.length * 2 // 3 if cut == "mid-chunk" else last.offset + last.length
    cut_log = tmp_path / "cut.mcap"
    cut_log.write_bytes(out.read_bytes()[:end])
    with open_log(cut_log) as log:
        assert [w.code for w in log.warnings] == ["mcap-truncated"]
        plan = _plan(log, rig)
        found = log.read_units(frozenset(plan.topics))
        assert found is not None and len(found) >= 3
        kinds = {u.kind for u in found}
        assert kinds == ({"mcap-chunk", "mcap-cut-chunk"} if cut == "mid-chunk" else {"mcap-chunk"})
        chunked = {
            jobs: [_comparable(i) for i in parallel_read.iter_items(log, plan, jobs=jobs)]
            for jobs in (1, 2)
        }
        monkeypatch.setattr(type(log), "read_units", lambda self, topics: None)
        plain = [_comparable(i) for i in parallel_read.iter_items(log, plan, jobs=1)]
    assert len(plain) > 100
    assert chunked[1] == plain
    assert chunked[2] == plain


REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize(
    ("log_name", "kind"),
    [("vlp16_short.bag", "rosbag1-chunk"), ("vlp16_short_ros2", "sqlite-rows")],
)
def test_bag_units_through_the_registry(
    log_name: str, kind: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """ROS 1 chunks and SQLite row ranges go through the same registry and merge as MCAP
    chunks: serial, parallel and a plain message-by-message read give the same items."""
    from syncaudit.rig import load_rig

    sample = REPO / "sample_logs"
    log_path = sample / log_name
    rig = load_rig(sample / f"{log_name}.rig.yaml")
    monkeypatch.setattr(parallel_read, "GROUP_BYTES", 50_000)
    monkeypatch.setattr(sqlite_rows, "WORKER_UNIT_BYTES", 1 << 19)  # several in 2.8 MB
    with open_log(log_path) as log:
        plan = _plan(log, rig)
        units = log.read_units(frozenset(plan.topics))
        assert units is not None and {u.kind for u in units} == {kind}
        assert len(units) > 1
        chunked = {
            jobs: [_comparable(i) for i in parallel_read.iter_items(log, plan, jobs=jobs)]
            for jobs in (1, 2)
        }
        monkeypatch.setattr(type(log), "read_units", lambda self, topics: None)
        plain = [_comparable(i) for i in parallel_read.iter_items(log, plan, jobs=1)]
    assert len(plain) > 50
    assert chunked[1] == plain
    assert chunked[2] == plain
