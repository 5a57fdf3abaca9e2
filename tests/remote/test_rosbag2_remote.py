"""ROS 2 bag prefixes over a real loopback Range server: MCAP storage read by ranges across
its files (rosbags-written, split in two), SQLite storage downloaded whole, saying why."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from logs.test_mcap_bag import _to_bag
from syncaudit.audit.run import audit_log
from syncaudit.fleet.gate import GateOptions, run_gate
from syncaudit.fleet.policy import parse_policy
from syncaudit.logs import open_log
from syncaudit.logs import parallel as parallel_read
from syncaudit.logs.mcap import remote as mcap_remote
from syncaudit.logs.ros2.remote import SQLITE_REASON, RemoteMcapBag, file_url
from syncaudit.remote.file import RemoteUnindexedError
from syncaudit.rig import Rig
from syncaudit.simulate.rig_file import rig_from_truth
from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log

from .conftest import ServerState, fetched

REPO = Path(__file__).resolve().parents[2]
SAMPLES = REPO / "sample_logs"
POLICY = {
    "vehicle_pattern": r"bags/(?P<vehicle>[^/]+)/",
    "defaults": {"lidar": {"rpm": {"min": 500, "max": 700}}},
}


@pytest.fixture(scope="module")
def split_bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Rig]:
    """(bag folder of two MCAP files written by rosbags, its rig)."""
    root = tmp_path_factory.mktemp("ros2")
    bare = root / "log.mcap"
    truth = simulate_sync_log(bare, SyncSimConfig(seed=71, duration_s=3.0, lidar_model="VLP-16"))
    folder = root / "bag"
    _to_bag(bare, folder, 2)
    return folder, rig_from_truth(truth)


def _serve(folder: Path, root: Path) -> None:
    (root / "bags").mkdir()
    (root / "bags" / folder.name).symlink_to(folder)


def _without_path(result: Any) -> dict[str, Any]:
    data: dict[str, Any] = result.to_dict()
    data.pop("path", None)
    return data


def test_file_url_keeps_the_prefix_query() -> None:
    assert file_url("https://h/b/bag/?sig=1", "a.mcap") == "https://h/b/bag/a.mcap?sig=1"
    assert file_url("https://h/b/bag", "a.mcap") == "https://h/b/bag/a.mcap"
    assert file_url("s3://k/bag/metadata.yaml", "a.mcap") == "s3://k/bag/a.mcap"


@pytest.mark.parametrize("jobs", [1, 2])
def test_an_mcap_bag_prefix_is_read_by_ranges_and_audits_as_the_folder(
    http_root: tuple[str, ServerState],
    split_bag: tuple[Path, Rig],
    jobs: int,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    base, state = http_root
    folder, rig = split_bag
    _serve(folder, state.root)
    monkeypatch.setattr(mcap_remote, "RANGE_BYTES", 1 << 20)  # several runs per file
    monkeypatch.setattr(parallel_read, "GROUP_BYTES", 1 << 20)
    url = f"{base}/bags/{folder.name}/?token=t0ken"
    with open_log(url) as log:  # its fetch statistics cover the audit's own open
        remote = audit_log(url, rig, jobs=jobs)
        stats = fetched(log)
    local = audit_log(folder, rig, jobs=jobs)
    assert _without_path(remote) == _without_path(local)
    assert remote.to_dict()["path"] == f"{base}/bags/{folder.name}"
    files = sorted(folder.glob("*.mcap"))
    assert len(files) == 2
    assert stats["size_bytes"] == sum(f.stat().st_size for f in files)
    assert stats["fetched_bytes"] == state.served_bytes  # metadata.yaml and both files
    assert 0 < stats["chunks_fetched"] == stats["chunks_total"]
    assert stats["fetched_bytes"] <= 1.05 * stats["needed_chunk_bytes"] + (64 << 10)
    assert all(" bytes=" in r and "t0ken" in r for r in state.requests)
    asked = {r.split("?")[0] for r in state.requests}
    assert asked == {
        f"/bags/{folder.name}/{n}" for n in ["metadata.yaml", *(f.name for f in files)]
    }
    with open_log(url) as log:
        assert isinstance(log, RemoteMcapBag)
        units = log.read_units(frozenset(log.topics))
        assert units and {u.source for u in units} == {
            f"{base}/bags/{folder.name}/{f.name}" for f in files
        }


def test_a_sqlite_bag_prefix_is_downloaded_whole_saying_why_once(
    http_root: tuple[str, ServerState], tmp_path: Path
) -> None:
    base, state = http_root
    bag = state.root / "bags" / "car" / "vlp16_short_ros2"
    bag.mkdir(parents=True)
    for file in (SAMPLES / "vlp16_short_ros2").iterdir():
        (bag / file.name).symlink_to(file)
    with pytest.raises(RemoteUnindexedError, match="SQLite storage") as err:
        open_log(f"{base}/bags/car/vlp16_short_ros2")
    assert str(err.value).count("downloaded whole") == 1
    policy = parse_policy(POLICY, "policy.yaml")
    summary = tmp_path / "summary.json"
    run_gate(
        [f"{base}/bags/"],
        policy,
        GateOptions(db=None, json_out=summary, jobs=1),
    )
    (log,) = json.loads(summary.read_text())["logs"]
    read = log["remote_read"]
    assert read["ranged"] is False and read["whole_reason"] == SQLITE_REASON
    assert log.get("error") is None
    assert json.dumps(log).count("random") + json.dumps(log).count("B-tree") == 1


def test_a_url_that_is_no_log_says_so(http_root: tuple[str, ServerState]) -> None:
    from syncaudit.errors import LogOpenError

    base, state = http_root
    (state.root / "notes.txt").write_text("hello")
    with pytest.raises(LogOpenError, match=r"notes.txt: neither an .mcap/.bag file nor a ROS 2"):
        open_log(f"{base}/notes.txt?sig=secret")


def test_the_gate_reads_an_mcap_bag_prefix_by_ranges(
    http_root: tuple[str, ServerState], split_bag: tuple[Path, Rig], tmp_path: Path
) -> None:
    base, state = http_root
    folder, rig = split_bag
    bag = state.root / "bags" / "car9" / folder.name
    bag.mkdir(parents=True)  # a real folder: the listing does not follow folder links
    for file in folder.iterdir():
        (bag / file.name).symlink_to(file)
    rig_file = tmp_path / "rig.json"
    rig_file.write_text(rig.model_dump_json())
    policy = parse_policy({**POLICY, "default_rig": str(rig_file)}, "policy.yaml")
    summary = tmp_path / "summary.json"
    run = run_gate([f"{base}/bags/"], policy, GateOptions(db=None, json_out=summary, jobs=2))
    (log,) = json.loads(summary.read_text())["logs"]
    assert log["path"] == f"{base}/bags/car9/{folder.name}" and run.logs[0].error is None
    read = log["remote_read"]
    assert read["ranged"] is True and read["whole_reason"] == ""
    assert read["chunks_fetched"] == read["chunks_total"] > 0
    assert read["size_bytes"] == sum(f.stat().st_size for f in folder.glob("*.mcap"))
    files = [r for r in state.requests if r.split()[0].endswith((".mcap", ".yaml"))]
    assert files and all(" bytes=" in r for r in files)  # (the rest: folder listings)


@pytest.mark.parametrize(
    ("edit", "words"),
    [
        (("version: ", "version: 99 #"), "rosbag2 metadata version 99 is newer than this tool"),
        (("storage_identifier: mcap", "storage_identifier: ''"), None),
    ],
)
def test_a_remote_prefix_follows_the_local_readers_metadata_rules(
    http_root: tuple[str, ServerState],
    split_bag: tuple[Path, Rig],
    tmp_path: Path,
    edit: tuple[str, str],
    words: str | None,
) -> None:
    """One parser for metadata.yaml: a version newer than the tool reads is refused, and a
    blank storage (some rosbag2 versions) is read from the files' names, with a warning."""
    from syncaudit.errors import LogOpenError

    base, state = http_root
    folder = tmp_path / "edited"
    folder.mkdir()
    source, _ = split_bag
    for file in source.iterdir():
        (folder / file.name).symlink_to(file)
    (folder / "metadata.yaml").unlink()
    text = (source / "metadata.yaml").read_text()
    assert edit[0] in text
    (folder / "metadata.yaml").write_text(text.replace(edit[0], edit[1], 1))
    _serve(folder, state.root)
    url = f"{base}/bags/{folder.name}"
    if words is not None:
        with pytest.raises(LogOpenError, match=words):
            open_log(url)
        return
    with open_log(url) as log:
        assert isinstance(log, RemoteMcapBag)
        assert [w.code for w in log.warnings] == ["rosbag2-storage-inferred"]
        assert "read by their names" in log.warnings[0].message
