"""Log writers: round trips through `open_log` in every format, atomic publication."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from syncaudit.errors import ConfigError, OutputError, UnknownTypeError
from syncaudit.logs import open_log
from syncaudit.writers.log_writer import FORMATS, BagCompression, LogFormat, LogWriter, open_writer

NAMES: dict[str, str] = {
    "mcap": "out.mcap",
    "mcap-ros1": "out1.mcap",
    "db3": "bag2",
    "bag": "out.bag",
}


def _data(msg: Any) -> Any:
    return msg.data


def _write_sample(writer: LogWriter) -> dict[str, list[tuple[int, bytes]]]:
    """Write a few messages on three topics; return what was written, per topic."""
    writer.add_topic("/cam/image_raw", "sensor_msgs/msg/Image")
    writer.add_topic("/cam/trigger", "syncaudit_msgs/TriggerEvent")
    writer.add_topic("/tf_static", "tf2_msgs/msg/TFMessage", latched=True)
    written: dict[str, list[tuple[int, bytes]]] = {t: [] for t in writer.topic_types}
    for i in range(5):
        stamp_ns = 1_700_000_000_000_000_000 + i * 100_000_123
        image = writer.new_msg(
            "sensor_msgs/msg/Image",
            header=writer.header(stamp_ns, "cam_optical"),
            height=2,
            width=3,
            encoding="mono8",
            step=3,
            data=np.arange(6, dtype=np.uint8) + i,
        )
        data = writer.serialize(image)
        writer.write("/cam/image_raw", stamp_ns + 5_000_000, data)
        written["/cam/image_raw"].append((stamp_ns + 5_000_000, data))
        trigger = writer.new_msg(
            "syncaudit_msgs/msg/TriggerEvent",
            header=writer.header(stamp_ns, "cam"),
            camera="cam",
            frame_sequence=i,
            lidar_packet_time=writer.time(stamp_ns - 1000),
            applied_delay=0.0125,
        )
        writer.write_msg("/cam/trigger", stamp_ns, trigger)
        written["/cam/trigger"].append((stamp_ns, writer.serialize(trigger)))
    tf = writer.new_msg(
        "tf2_msgs/msg/TFMessage",
        transforms=[writer.new_msg("geometry_msgs/msg/TransformStamped", child_frame_id="cam")],
    )
    writer.write_msg("/tf_static", 1_700_000_000_000_000_000, tf)
    written["/tf_static"].append((1_700_000_000_000_000_000, writer.serialize(tf)))
    return written


@pytest.mark.parametrize("fmt", FORMATS)
def test_round_trip(tmp_path: Path, fmt: LogFormat) -> None:
    path = tmp_path / NAMES[fmt]
    with open_writer(path, fmt) as writer:
        written = _write_sample(writer)
        encoding = writer.encoding
    assert encoding == ("ros1" if fmt in ("bag", "mcap-ros1") else "cdr")
    with open_log(path) as log:
        assert set(log.topics) == set(written)
        assert log.topics["/cam/trigger"].msgtype == "syncaudit_msgs/msg/TriggerEvent"
        for topic, info in log.topics.items():
            assert info.count == len(written[topic])
            assert info.encoding == encoding
            assert info.has_definition
        read: dict[str, list[tuple[int, bytes]]] = {t: [] for t in written}
        triggers: list[Any] = []
        for raw in log.messages():
            read[raw.topic].append((raw.log_time_ns, bytes(raw.data)))
            if raw.topic == "/cam/trigger":
                triggers.append(log.deserialize(raw))
            if raw.topic == "/cam/image_raw":
                image: Any = log.deserialize(raw)
                assert image.encoding == "mono8"
                assert image.header.frame_id == "cam_optical"
    assert read == written
    assert [t.frame_sequence for t in triggers] == list(range(5))
    first = triggers[0]
    assert first.applied_delay == 0.0125
    assert (first.header.stamp.sec, first.header.stamp.nanosec) == (1_700_000_000, 0)
    assert (first.lidar_packet_time.sec, first.lidar_packet_time.nanosec) == (
        1_699_999_999,
        999_999_000,
    )
    # Only the published output remains beside it: no temporary leftovers.
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


def test_format_from_suffix(tmp_path: Path) -> None:
    with open_writer(tmp_path / "x.bag", None) as writer:
        assert writer.fmt == "bag"
    with open_writer(tmp_path / "y.mcap", None) as writer:
        assert writer.fmt == "mcap"
    with open_writer(tmp_path / "z", None) as writer:
        assert writer.fmt == "db3"
    with pytest.raises(ConfigError):
        open_writer(tmp_path / "w.txt", None)


@pytest.mark.parametrize("fmt", FORMATS)
def test_failure_leaves_no_output(tmp_path: Path, fmt: LogFormat) -> None:
    path = tmp_path / NAMES[fmt]
    with pytest.raises(RuntimeError, match="boom"), open_writer(path, fmt) as writer:
        _write_sample(writer)
        raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("fmt", FORMATS)
def test_existing_output_not_clobbered(tmp_path: Path, fmt: LogFormat) -> None:
    path = tmp_path / NAMES[fmt]
    with open_writer(path, fmt) as writer:
        writer.add_topic("/a", "std_msgs/msg/String")
        writer.write_msg("/a", 1, writer.new_msg("std_msgs/msg/String", data="first"))
    with pytest.raises(OutputError, match="exists"):
        open_writer(path, fmt)
    with open_writer(path, fmt, overwrite=True) as writer:
        writer.add_topic("/b", "std_msgs/msg/String")
        writer.write_msg("/b", 2, writer.new_msg("std_msgs/msg/String", data="second"))
    with open_log(path) as log:
        assert set(log.topics) == {"/b"}
        assert [_data(log.deserialize(m)) for m in log.messages()] == ["second"]
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


def test_target_appearing_while_writing_is_kept(tmp_path: Path) -> None:
    path = tmp_path / "race.mcap"
    writer = open_writer(path, "mcap")
    writer.add_topic("/a", "std_msgs/msg/String")
    path.write_bytes(b"someone else's")
    with pytest.raises(OutputError, match="appeared while writing"):
        writer.close()
    assert path.read_bytes() == b"someone else's"
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


def test_overwrite_refuses_a_file_the_tool_did_not_write(tmp_path: Path) -> None:
    path = tmp_path / "out"
    path.write_text("a file where the bag directory goes")
    with pytest.raises(OutputError, match=r"did not write.*not replacing it"):
        open_writer(path, "db3", overwrite=True)
    assert path.read_text() == "a file where the bag directory goes"
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_overwrite_replaces_own_outputs_of_other_kinds(tmp_path: Path) -> None:
    path = tmp_path / "out"
    with open_writer(path, "bag") as writer:
        writer.add_topic("/a", "std_msgs/msg/String")
    with open_writer(path, "db3", overwrite=True) as writer:
        writer.add_topic("/a", "std_msgs/msg/String")
    assert (path / "metadata.yaml").is_file()
    with open_writer(path, "mcap", overwrite=True) as writer:
        writer.add_topic("/a", "std_msgs/msg/String")
    assert path.is_file()
    with open_log(path) as log:
        assert log.summary.container == "mcap"
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_a_folder_the_tool_did_not_write_is_never_replaced(tmp_path: Path) -> None:
    path = tmp_path / "X.mcap"
    (path / "sub").mkdir(parents=True)
    (path / "sub" / "precious").write_text("mine")
    for fmt in ("mcap", "mcap-ros1"):
        with pytest.raises(OutputError, match="not replacing it"):
            open_writer(path, fmt, overwrite=True)
    assert (path / "sub" / "precious").read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["X.mcap"]


def test_db3_names_and_mismatched_suffixes(tmp_path: Path) -> None:
    from syncaudit.writers.log_writer import log_target

    assert log_target(tmp_path / "p.db3", "db3") == tmp_path / "p"
    assert log_target(tmp_path / "p.mcap", "mcap") == tmp_path / "p.mcap"
    with open_writer(log_target(tmp_path / "p.db3", "db3"), None) as writer:
        writer.add_topic("/a", "std_msgs/msg/String")
    assert (tmp_path / "p" / "p.db3").is_file() and not (tmp_path / "p.db3").exists()
    with pytest.raises(ConfigError, match="format is 'db3'"):
        open_writer(tmp_path / "x.mcap", "db3")
    with pytest.raises(ConfigError, match="format is 'mcap'"):
        open_writer(tmp_path / "x.bag", "mcap")


def test_full_disk_names_the_output(tmp_path: Path) -> None:
    """sqlite's OperationalError (a full disk) becomes an OutputError naming the bag."""
    import sqlite3

    from syncaudit.writers.outputs import OutputSet

    outputs = OutputSet()
    target = tmp_path / "bag"
    full = r"bag: cannot write \(database or disk is full\)"
    with pytest.raises(OutputError, match=full), outputs, outputs.writing(target):
        raise sqlite3.OperationalError("database or disk is full")
    assert list(tmp_path.iterdir()) == []


def test_misuse_is_refused(tmp_path: Path) -> None:
    with open_writer(tmp_path / "m.mcap") as writer:
        writer.add_topic("/a", "std_msgs/String")
        assert writer.topic_types["/a"] == "std_msgs/msg/String"
        with pytest.raises(ValueError, match="already added"):
            writer.add_topic("/a", "std_msgs/msg/String")
        with pytest.raises(UnknownTypeError):
            writer.add_topic("/b", "nobody_msgs/msg/Nothing")
        with pytest.raises(KeyError):
            writer.write("/nope", 1, b"")
        with pytest.raises(TypeError):
            writer.write_msg("/a", 1, writer.new_msg("std_msgs/msg/Int32", data=3))
        with pytest.raises(TypeError):
            writer.new_msg("std_msgs/msg/String", value="x")
        with pytest.raises(ValueError, match="outside"):
            writer.write("/a", -1, b"")
    with pytest.raises(ValueError, match="closed"):
        writer.write("/a", 1, b"")


@pytest.mark.parametrize("compression", ["lz4", "bz2"])
def test_bag_chunks_compressed_as_asked(tmp_path: Path, compression: BagCompression) -> None:
    """A ROS 1 bag with lz4 / bz2 chunks (as `rosbag record --lz4`) holds what was written."""
    path = tmp_path / "c.bag"
    with open_writer(path, "bag", bag_compression=compression) as writer:
        written = _write_sample(writer)
    with open_log(path) as log:
        read: dict[str, list[tuple[int, bytes]]] = {t: [] for t in written}
        for raw in log.messages():
            read[raw.topic].append((raw.log_time_ns, bytes(raw.data)))
    assert read == written
    # Every chunk record's header names its compression (and none says "none").
    raw_bytes = path.read_bytes()
    assert (b"compression=" + compression.encode()) in raw_bytes
    assert b"compression=none" not in raw_bytes
