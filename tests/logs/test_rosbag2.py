"""ROS 2 bags written with rosbags: mcap storage, recorded definitions, split bags, versions."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from rosbags.rosbag2 import Reader, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode, StoragePlugin
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from syncaudit.logs import LogReader, open_log
from syncaudit.logs.typesys import TypeRegistry

Untouched = Callable[[Path], Path]
Message = tuple[str, int, bytes]  # topic, log time, bytes


def write_bag(
    path: Path,
    store: Typestore,
    msgtype: str,
    messages: list[Message],
    *,
    version: int = 9,
    storage: StoragePlugin = StoragePlugin.SQLITE3,
    compression: CompressionMode = CompressionMode.NONE,
) -> Path:
    """Write a rosbag2 directory with rosbags; every topic has type `msgtype`."""
    writer = Writer(path, version=version, storage_plugin=storage)  # type: ignore[arg-type]
    writer.set_compression(compression, CompressionFormat.ZSTD)
    with writer:
        conns: dict[str, Any] = {}
        for topic, stamp, data in messages:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(conns[topic], stamp, data)
    return path


def probe_messages(
    probe: Any, stamps: list[int], topics: tuple[str, ...] = ("/a", "/b")
) -> list[Message]:
    return [(topics[i % len(topics)], t, probe.make(i)) for i, t in enumerate(stamps)]


def stream(log: LogReader, *args: Any) -> list[Message]:
    return [(m.topic, m.log_time_ns, bytes(m.data)) for m in log.messages(*args)]


@pytest.mark.parametrize("version", [8, 9])
@pytest.mark.parametrize("form", ["directory", "file"])
def test_sqlite3_bag_with_recorded_definitions(
    tmp_path: Path, ros2_store: Typestore, probe: Any, version: int, form: str, untouched: Untouched
) -> None:
    """Version 8/9 bags store definitions: a type unknown to ROS and schemas/ still decodes."""
    assert not TypeRegistry(ros1=False).knows(probe.type)  # only the bag can define it
    msgs = probe_messages(probe, [100, 150, 200, 250, 300])
    bag = untouched(write_bag(tmp_path / "bag", ros2_store, probe.type, msgs, version=version))
    path = bag if form == "directory" else next(bag.glob("*.db3"))
    with open_log(path) as log:
        s = log.summary
        assert (s.container, s.message_count, s.start_ns, s.end_ns) == (
            "rosbag2-sqlite3",
            5,
            100,
            300,
        )
        assert {n: (t.msgtype, t.count, t.has_definition) for n, t in log.topics.items()} == {
            "/a": (probe.type, 3, True),
            "/b": (probe.type, 2, True),
        }
        assert stream(log) == msgs
        assert stream(log, "/b", 150, 250) == [msgs[1]]
        got: Any = log.deserialize(next(log.messages(start_ns=200)))
        assert (got.seq, got.label) == (2, "p2")
        assert log.warnings == []


def test_recorded_definition_wins_over_schemas_dir(tmp_path: Path) -> None:
    text = "uint32 seq\nuint8[] buf\n"
    store = get_typestore(Stores.ROS2_HUMBLE)
    store.register(get_types_from_msg(text, "ouster_sensor_msgs/msg/PacketMsg"))
    cls = store.types["ouster_sensor_msgs/msg/PacketMsg"]
    data = bytes(store.serialize_cdr(cls(seq=9, buf=np.arange(3, dtype=np.uint8)), cls.__msgtype__))
    bag = write_bag(tmp_path / "bag", store, cls.__msgtype__, [("/pk", 1, data)])
    with open_log(bag) as log:
        got: Any = log.deserialize(next(log.messages()))
    assert got.seq == 9 and list(got.buf) == [0, 1, 2]


def test_mcap_storage_directory_and_its_bare_file(
    tmp_path: Path, ros2_store: Typestore, probe: Any, untouched: Untouched
) -> None:
    msgs = probe_messages(probe, list(range(1_000, 1_400, 10)))
    bag = untouched(
        write_bag(tmp_path / "bag", ros2_store, probe.type, msgs, storage=StoragePlugin.MCAP)
    )
    with open_log(bag) as log:
        assert log.summary.container == "rosbag2-mcap"
        assert (log.summary.message_count, log.summary.start_ns, log.summary.end_ns) == (
            40,
            1_000,
            1_390,
        )
        assert all(t.has_definition for t in log.topics.values())
        assert stream(log) == msgs
        assert stream(log, ["/a"], 1_100, 1_200) == [
            m for m in msgs if m[0] == "/a" and 1_100 <= m[1] < 1_200
        ]
        assert log.deserialize(next(log.messages())).label == "p0"  # type: ignore[attr-defined]
    (bare,) = bag.glob("*.mcap")
    with open_log(bare) as log:  # a bare rosbag2 .mcap is an MCAP file
        assert log.summary.container == "mcap"
        assert log.summary.message_count == 40 and log.warnings == []
        assert stream(log) == msgs
        assert log.deserialize(next(log.messages())).label == "p0"  # type: ignore[attr-defined]


def split_bag(tmp_path: Path, parts: list[Path], name: str = "split") -> Path:
    """Join single-file bags into one split bag: one directory, metadata listing every file."""
    target = tmp_path / name
    target.mkdir()
    infos = [
        yaml.safe_load((p / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        for p in parts
    ]
    meta = dict(infos[0])
    files = []
    for index, (part, info) in enumerate(zip(parts, infos, strict=True)):
        (src,) = (part / f for f in info["relative_file_paths"])
        dst = f"{name}_{index}{''.join(src.suffixes)}"
        shutil.copyfile(src, target / dst)
        files.append({**info["files"][0], "path": dst})
    start = min(f["starting_time"]["nanoseconds_since_epoch"] for f in files)
    end = max(
        f["starting_time"]["nanoseconds_since_epoch"] + f["duration"]["nanoseconds"] for f in files
    )
    counts: dict[str, int] = {}
    for info in infos:
        for topic in info["topics_with_message_count"]:
            name_ = topic["topic_metadata"]["name"]
            counts[name_] = counts.get(name_, 0) + topic["message_count"]
    meta.update(
        relative_file_paths=[f["path"] for f in files],
        files=files,
        message_count=sum(counts.values()),
        starting_time={"nanoseconds_since_epoch": start},
        duration={"nanoseconds": end - start},
        topics_with_message_count=[
            {**t, "message_count": counts[t["topic_metadata"]["name"]]}
            for t in infos[0]["topics_with_message_count"]
        ],
    )
    (target / "metadata.yaml").write_text(yaml.safe_dump({"rosbag2_bagfile_information": meta}))
    return target


@pytest.mark.parametrize(
    ("storage", "compression"),
    [
        (StoragePlugin.SQLITE3, CompressionMode.NONE),
        (StoragePlugin.SQLITE3, CompressionMode.MESSAGE),
        (StoragePlugin.SQLITE3, CompressionMode.FILE),
        (StoragePlugin.MCAP, CompressionMode.NONE),
    ],
    ids=["sqlite3", "sqlite3-message-zstd", "sqlite3-file-zstd", "mcap"],
)
def test_split_bag_reads_in_log_time_order(
    tmp_path: Path,
    ros2_store: Typestore,
    probe: Any,
    storage: StoragePlugin,
    compression: CompressionMode,
    untouched: Untouched,
) -> None:
    """Two files whose times interleave at the split (as a busy recorder writes them)."""
    first = probe_messages(probe, [*range(0, 100, 10), 105, 125])
    second = probe_messages(probe, [100, 115, 120, *range(130, 200, 10)])
    parts = [
        write_bag(
            tmp_path / f"part{i}",
            ros2_store,
            probe.type,
            msgs,
            storage=storage,
            compression=compression,
        )
        for i, msgs in enumerate([first, second])
    ]
    bag = untouched(split_bag(tmp_path, parts))
    everything = sorted(first + second, key=lambda m: m[1])

    with Reader(bag) as plain:  # rosbags alone concatenates the files: out of order here
        naive = [t for _c, t, _d in plain.messages()]
    assert naive != sorted(naive)

    with open_log(bag) as log:
        s = log.summary
        assert (s.message_count, s.start_ns, s.end_ns) == (len(everything), 0, 190)
        assert {n: t.count for n, t in log.topics.items()} == {"/a": 11, "/b": 11}
        assert stream(log) == everything
        assert stream(log, None, 95, 131) == [m for m in everything if 95 <= m[1] < 131]
        assert stream(log, ["/b"]) == [m for m in everything if m[0] == "/b"]
        assert log.deserialize(next(log.messages(start_ns=105))).label == "p10"  # type: ignore[attr-defined]


def _as_version(info: dict[str, Any], version: int, bag_name: str) -> dict[str, Any]:
    """Rewrite rosbags' version-9 metadata into what a rosbag2 of `version` wrote."""
    meta = dict(info, version=version)
    topics = []
    for entry in info["topics_with_message_count"]:
        topic = dict(entry["topic_metadata"])
        if version < 7:
            topic.pop("type_description_hash", None)
        if version < 4:
            topic.pop("offered_qos_profiles", None)
        elif version < 9:
            topic["offered_qos_profiles"] = ""  # a YAML string before version 9
        topics.append({**entry, "topic_metadata": topic})
    meta["topics_with_message_count"] = topics
    if version < 8:
        meta.pop("ros_distro", None)
    if version < 6:
        meta.pop("custom_data", None)
    if version < 5:
        meta.pop("files", None)
    if version < 4:  # paths were relative to the bag's parent folder
        meta["relative_file_paths"] = [f"{bag_name}/{p}" for p in info["relative_file_paths"]]
    if version < 3:
        meta.pop("compression_format", None)
        meta.pop("compression_mode", None)
    return meta


@pytest.mark.parametrize("version", range(1, 10))
def test_every_rosbag2_metadata_version(
    tmp_path: Path, ros2_store: Typestore, probe: Any, version: int
) -> None:
    msgs = probe_messages(probe, [5, 6, 7, 9])
    bag = write_bag(tmp_path / "bag", ros2_store, probe.type, msgs)
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    meta = _as_version(info, version, bag.name)
    (bag / "metadata.yaml").write_text(yaml.safe_dump({"rosbag2_bagfile_information": meta}))
    with open_log(bag) as log:
        assert (log.summary.message_count, log.summary.start_ns, log.summary.end_ns) == (4, 5, 9)
        assert {n: t.count for n, t in log.topics.items()} == {"/a": 2, "/b": 2}
        assert stream(log) == msgs


def test_empty_bags(tmp_path: Path, ros2_store: Typestore) -> None:
    """A bag with a topic and no messages: count 0, no time range, nothing streamed."""
    from rosbags.rosbag1 import Writer as Ros1Writer

    bag2 = tmp_path / "empty2"
    with Writer(bag2, version=9) as writer:
        writer.add_connection("/a", "std_msgs/msg/String", typestore=ros2_store)
    bag1 = tmp_path / "empty1.bag"
    with Ros1Writer(bag1) as writer1:
        writer1.add_connection(
            "/a", "std_msgs/msg/String", typestore=get_typestore(Stores.ROS1_NOETIC)
        )
    for path in (bag2, next(bag2.glob("*.db3")), bag1):
        with open_log(path) as log:
            s = log.summary
            assert (s.message_count, s.start_ns, s.end_ns) == (0, None, None), path
            assert list(log.messages()) == []
            assert {n: t.count for n, t in log.topics.items()} == {"/a": 0}
