"""MCAP read straight from a URL (logs/mcap_remote.py) over a real loopback Range server:
the same audit as the local file, only the needed chunks fetched, drops resumed or refused."""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any

import pytest

from syncaudit.audit.run import audit_log
from syncaudit.errors import LogOpenError, LogReadError
from syncaudit.logs import open_log
from syncaudit.logs.mcap import remote as mcap_remote
from syncaudit.logs.mcap.remote import KIND, RemoteMcapLog, coalesce_units
from syncaudit.logs.model import ReadUnit
from syncaudit.logs.unit_readers import open_unit_reader
from syncaudit.rig import load_rig

from .conftest import ServerState, fetched

REPO = Path(__file__).resolve().parents[2]
SAMPLES = REPO / "sample_logs"
NAMES = ["pandar40p_adaptive.mcap", "vlp16_three_cameras.mcap"]


def _without_path(result: Any) -> dict[str, Any]:
    data: dict[str, Any] = result.to_dict()
    data.pop("path", None)
    return data


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("jobs", [1, 2])
def test_remote_audit_equals_the_local_audit(
    http_root: tuple[str, ServerState], name: str, jobs: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    base, state = http_root
    (state.root / name).symlink_to(SAMPLES / name)
    # Runs of ~2 chunks: several units, so jobs=2 reads them in forked workers.
    monkeypatch.setattr(mcap_remote, "RANGE_BYTES", 600_000)
    rig = load_rig(SAMPLES / f"{name}.rig.yaml")
    url = f"{base}/{name}?X-Amz-Signature=secret"
    with open_log(url) as log:  # its fetch statistics cover the audit's own open
        remote = audit_log(url, rig, jobs=jobs)
        stats = fetched(log)
    local = audit_log(SAMPLES / name, rig, jobs=jobs)
    assert _without_path(remote) == _without_path(local)
    assert remote.to_dict()["path"] == f"{base}/{name}"  # no query string
    # Every byte the server sent was counted, in the parent and in the workers.
    assert stats["fetched_bytes"] == state.served_bytes == state.ranged_bytes
    assert stats["chunks_fetched"] == stats["chunks_total"] > 0
    assert stats["fetched_bytes"] <= 1.05 * stats["needed_chunk_bytes"] + (32 << 10)
    assert all(" bytes=" in r for r in state.requests)  # ranged reads only


def test_units_are_runs_of_chunks_and_read_back_every_message(
    http_root: tuple[str, ServerState], monkeypatch: pytest.MonkeyPatch
) -> None:
    base, state = http_root
    name = "pandar40p_adaptive.mcap"
    (state.root / name).symlink_to(SAMPLES / name)
    monkeypatch.setattr(mcap_remote, "RANGE_BYTES", 600_000)
    with open_log(SAMPLES / name) as local_log:
        topics = frozenset(local_log.topics)
        chunks = local_log.read_units(topics)
        want = [(m.topic, m.log_time_ns, bytes(m.data)) for m in local_log.messages(topics)]
    assert chunks is not None
    with open_log(f"{base}/{name}") as log:
        assert isinstance(log, RemoteMcapLog)
        units = log.read_units(topics)
        channels = log.unit_channels(topics)
        # messages() in the parent: chunk by chunk, merged in log time.
        assert [(m.topic, m.log_time_ns, bytes(m.data)) for m in log.messages(topics)] == want
    assert units is not None and len(units) > 1
    assert all(u.kind == KIND and u.source == f"{base}/{name}" for u in units)
    assert sum(u.length for u in units) < 1.05 * sum(c.length for c in chunks)
    assert {c.offset for c in chunks} >= {u.offset for u in units}
    reader = open_unit_reader(KIND, f"{base}/{name}")
    got = []
    for unit in units:
        for log_time, _index, cid, data in reader.messages(unit, channels):
            got.append((channels[cid].topic, log_time, bytes(data)))
    assert sorted(got, key=lambda m: m[1]) == sorted(want, key=lambda m: m[1])


def test_coalesce_units_respects_gap_and_run_size() -> None:
    def chunk(offset: int, length: int, t: int) -> ReadUnit:
        return ReadUnit("f", "mcap-chunk", offset, length, t, t + 5, length)

    chunks = [chunk(0, 100, 10), chunk(110, 100, 20), chunk(1_000_000, 50, 5)]
    runs = coalesce_units(chunks, "http://h/f.mcap")
    assert [(r.offset, r.length, r.start_ns, r.end_ns) for r in runs] == [
        (0, 210, 10, 25),
        (1_000_000, 50, 5, 10),
    ]
    big = [chunk(i * 10 << 20, 10 << 20, i) for i in range(5)]
    assert [r.length for r in coalesce_units(big, "u")] == [20 << 20] * 2 + [10 << 20]


def test_a_dropped_reply_resumes_where_it_stopped(http_root: tuple[str, ServerState]) -> None:
    base, state = http_root
    name = "vlp16_three_cameras.mcap"
    (state.root / name).symlink_to(SAMPLES / name)
    state.drop_after_bytes, state.drops_left = 5000, 2  # two drops, then good replies
    rig = load_rig(SAMPLES / f"{name}.rig.yaml")
    remote = audit_log(f"{base}/{name}", rig, jobs=1)
    assert _without_path(remote) == _without_path(audit_log(SAMPLES / name, rig, jobs=1))
    asked = [r.split("bytes=")[1].split("-") for r in state.requests]
    ranges = {(int(a), int(b)) for a, b in asked}
    resumed = [(a, b) for a, b in ranges if (a - 5000, b) in ranges]
    assert len(resumed) == 2  # the dropped run was asked again from where it stopped, twice


def test_a_connection_dropped_every_time_is_a_read_error_naming_url_and_range(
    http_root: tuple[str, ServerState],
) -> None:
    base, state = http_root
    name = "vlp16_three_cameras.mcap"
    (state.root / name).symlink_to(SAMPLES / name)
    state.drop_after_bytes = 1000
    with pytest.raises(LogReadError, match=rf"^{base}/{name}: reading bytes \d+-\d+ failed 3 "):
        audit_log(f"{base}/{name}?token=secret", load_rig(SAMPLES / f"{name}.rig.yaml"), jobs=2)


def test_missing_log_and_a_server_without_range_support(
    http_root: tuple[str, ServerState],
) -> None:
    base, state = http_root
    with pytest.raises(LogOpenError, match=rf"^{base}/gone.mcap: no such log") as err:
        open_log(f"{base}/gone.mcap?token=secret")
    assert "secret" not in str(err.value) and err.value.exit_code == 2
    (state.root / "a.mcap").symlink_to(SAMPLES / NAMES[0])
    state.ignore_range = True
    with pytest.raises(LogReadError, match="does not honour Range") as read_err:
        open_log(f"{base}/a.mcap")
    assert read_err.value.exit_code == 3


def test_an_mcap_without_index_is_refused_for_a_whole_download(
    http_root: tuple[str, ServerState], tmp_path: Path
) -> None:
    from mcap.writer import Writer

    base, state = http_root
    path = state.root / "plain.mcap"
    with path.open("wb") as handle:
        writer = Writer(handle, use_chunking=False, use_summary_offsets=False)
        writer.start("ros2", "t")
        schema = writer.register_schema("std_msgs/msg/Int32", "ros2msg", b"int32 data")
        channel = writer.register_channel("/x", "cdr", schema)
        for index in range(10):
            writer.add_message(channel, index, random.Random(index).randbytes(8), index)
        writer.finish()
    with pytest.raises(mcap_remote.RemoteUnindexedError, match="cannot be read by ranges"):
        open_log(f"{base}/plain.mcap")


@pytest.mark.parametrize("jobs", [1, 2])
def test_ros1_bag_by_chunk_spans_audits_as_the_local_file(
    http_root: tuple[str, ServerState], jobs: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    from syncaudit.logs.ros1 import remote as rosbag1_remote

    base, state = http_root
    if jobs == 2:  # runs of one chunk span each: several units for the two workers
        monkeypatch.setattr(rosbag1_remote, "RANGE_BYTES", 1 << 20)
    name = "vlp16_short.bag"
    (state.root / name).symlink_to(SAMPLES / name)
    rig = load_rig(SAMPLES / f"{name}.rig.yaml")
    url = f"{base}/{name}"
    with open_log(url) as log:  # its fetch statistics cover the audit's own open
        remote = audit_log(url, rig, jobs=jobs)
        stats = fetched(log)
    assert _without_path(remote) == _without_path(audit_log(SAMPLES / name, rig, jobs=jobs))
    assert stats["fetched_bytes"] == state.served_bytes
    assert stats["chunks_fetched"] == stats["chunks_total"] > 1
    # Header, index section, one request per run: no scan, no per-chunk header read.
    assert stats["requests"] == 2 + (1 if jobs == 1 else stats["chunks_fetched"])
    assert stats["fetched_bytes"] <= stats["size_bytes"] + 4096


def test_ros1_bag_without_index_is_refused_for_a_whole_download(
    http_root: tuple[str, ServerState],
) -> None:
    base, state = http_root
    data = bytearray((SAMPLES / "vlp16_short.bag").read_bytes())
    at = data.index(b"index_pos=") + len(b"index_pos=")
    data[at : at + 8] = bytes(8)  # as a recording that was never closed
    (state.root / "open.bag").write_bytes(bytes(data))
    with pytest.raises(mcap_remote.RemoteUnindexedError, match="cannot be read by ranges"):
        open_log(f"{base}/open.bag")
