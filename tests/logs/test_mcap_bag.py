"""ROS 2 bag folders with MCAP storage (issue 13): one file or split into many, written by
rosbags' rosbag2 writer from a simulated log, audit exactly like the bare `.mcap`."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from syncaudit.audit.run import audit_log
from syncaudit.logs import open_log
from syncaudit.logs import parallel as parallel_read
from syncaudit.logs.mcap.reader import McapLog
from syncaudit.logs.ros2.mcap_storage import McapBag, open_mcap_bag
from syncaudit.logs.typesys import TypeRegistry
from syncaudit.logs.unit_readers import group_units
from syncaudit.simulate.rig_file import rig_from_truth
from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log
from syncaudit.writers.rosbag2_split import SplitBagWriter


@pytest.fixture(scope="module")
def bare(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, object]]:
    out = tmp_path_factory.mktemp("bare") / "log.mcap"
    truth = simulate_sync_log(out, SyncSimConfig(seed=71, duration_s=3.0, lidar_model="VLP-16"))
    return out, truth


def _to_bag(bare: Path, folder: Path, parts: int, *, reorder: bool = False) -> list[Path]:
    """Write the bare log's messages as a rosbag2 MCAP bag split into `parts` files by time.

    Each part is written by its own rosbags Writer (as rosbag2 does on a split, every file
    declares its channels anew); `reorder` declares them in reverse order in odd parts, so
    the files number their channels differently.
    """
    with open_log(bare) as log:
        assert isinstance(log, McapLog) and log.summary.start_ns is not None
        assert log.summary.end_ns is not None
        span = log.summary.end_ns - log.summary.start_ns + 1
        topics = sorted(log.topics)
        defs = {}
        for channel in log._channels.values():
            schema = log._schemas[channel.schema_id]
            defs[channel.topic] = (log.topics[channel.topic].msgtype, schema.data.decode())
        messages = list(log.messages())
        registry = TypeRegistry(ros1=False, log_types=log.log_types("cdr"), eager=True)
    bag = SplitBagWriter(folder, registry.store)
    for part in range(parts):
        lo = log.summary.start_ns + span * part // parts
        hi = log.summary.start_ns + span * (part + 1) // parts
        order = topics[::-1] if reorder and part % 2 else topics
        bag.start_part([(t, defs[t][0]) for t in order])
        for m in messages:
            if lo <= m.log_time_ns < hi:
                bag.write(m.topic, m.log_time_ns, bytes(m.data))
    bag.close()  # one metadata.yaml listing every part, as rosbag2 writes it after a split
    return bag.files


def _json(result: object) -> str:
    def strip(value: object) -> object:  # the path and container differ by design
        if isinstance(value, dict):
            return {k: strip(v) for k, v in value.items() if k not in ("path", "container")}
        if isinstance(value, list):
            return [strip(v) for v in value]
        return value

    return json.dumps(strip(result.to_dict()), sort_keys=True)  # type: ignore[attr-defined]


@pytest.mark.parametrize(("parts", "reorder"), [(1, False), (3, False), (3, True)])
def test_bag_folder_audits_like_the_bare_mcap(
    bare: tuple[Path, dict[str, object]],
    tmp_path: Path,
    parts: int,
    reorder: bool,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    path, truth = bare
    monkeypatch.setattr(parallel_read, "GROUP_BYTES", 300_000)  # several tasks per file
    folder = tmp_path / "bag"
    files = _to_bag(path, folder, parts, reorder=reorder)
    rig = rig_from_truth(truth)
    with open_mcap_bag(folder, files) as bag, open_log(path) as log:
        assert bag.summary.container == "rosbag2-mcap"
        assert bag.summary.message_count == log.summary.message_count
        assert {n: t.count for n, t in bag.topics.items()} == {
            n: t.count for n, t in log.topics.items()
        }
        topics = frozenset(bag.topics)
        units = bag.read_units(topics)
        if reorder:
            assert units is None  # channel ids differ between files: read serially
        else:
            assert units is not None and {u.source for u in units} == {str(f) for f in files}
            assert len(group_units(units, parallel_read.GROUP_BYTES)) > 1  # jobs=2 uses the pool
        same = [(m.topic, m.log_time_ns, bytes(m.data)) for m in bag.messages()]
        assert same == [(m.topic, m.log_time_ns, bytes(m.data)) for m in log.messages()]
    with open_log(folder) as opened:  # open_log takes the MCAP path for such folders
        assert isinstance(opened, McapBag)
    reference = audit_log(path, rig, jobs=1)
    for jobs in (1, 2):
        result = audit_log(folder, rig, jobs=jobs)
        assert _json(result) == _json(reference)
        assert result.frames().equals(reference.frames())


def test_split_bag_with_a_cut_last_file(
    bare: tuple[Path, dict[str, object]], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A recording that crashed: the last file of a split bag has no summary and ends
    inside a chunk. Every file still gives read units; the parallel read equals the serial
    one and holds every message before the cut."""
    path, truth = bare
    monkeypatch.setattr(parallel_read, "GROUP_BYTES", 300_000)
    folder = tmp_path / "bag"
    files = _to_bag(path, folder, 3)
    last = files[-1]
    data = last.read_bytes()
    last.write_bytes(data[: len(data) * 2 // 3])
    rig = rig_from_truth(truth)  # type: ignore[arg-type]
    with open_mcap_bag(folder, files) as bag:
        assert any(w.code == "mcap-truncated" for w in bag.warnings)
        units = bag.read_units(frozenset(bag.topics))
        assert units is not None and str(last) in {u.source for u in units}
        serial = [(m.topic, m.log_time_ns, bytes(m.data)) for m in bag.messages()]
    with open_log(path) as log:
        full = [(m.topic, m.log_time_ns, bytes(m.data)) for m in log.messages()]
    assert 0 < len(serial) < len(full) and serial == full[: len(serial)]
    results = [audit_log(folder, rig, jobs=jobs) for jobs in (1, 2)]
    assert _json(results[0]) == _json(results[1])
    monkeypatch.setattr(McapBag, "read_units", lambda self, topics: None)
    assert _json(audit_log(folder, rig, jobs=1)) == _json(results[0])


def test_blank_metadata_fields_read_by_the_mcap_path_or_refused_when_compressed(
    bare: tuple[Path, dict[str, object]], tmp_path: Path
) -> None:
    """A folder whose metadata.yaml leaves `storage_identifier` blank (some rosbag2
    versions) is read through its MCAP files with a warning naming the quirk; with a
    rosbag2 compression mode as well (rosbags, which refuses blank fields, would read it)
    it is one LogOpenError line."""
    import yaml

    from syncaudit.errors import LogOpenError

    folder = tmp_path / "bag"
    _to_bag(bare[0], folder, 2)
    meta_path = folder / "metadata.yaml"
    doc = yaml.safe_load(meta_path.read_text())
    info = doc["rosbag2_bagfile_information"]
    info["storage_identifier"] = ""
    meta_path.write_text(yaml.safe_dump(doc))
    with open_log(folder) as log:
        assert isinstance(log, McapBag)
        assert any("names storage" in w.message for w in log.warnings)
        assert log.summary.message_count == sum(t.count or 0 for t in log.topics.values())
    info["compression_mode"] = "FILE"
    info["compression_format"] = "zstd"
    meta_path.write_text(yaml.safe_dump(doc))
    with pytest.raises(LogOpenError, match=r"blank fields .* split into 2 files or compressed"):
        open_log(folder)
