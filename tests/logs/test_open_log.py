"""open_log on the real recordings: summaries equal what the bags say, streaming, selection."""

from __future__ import annotations

import inspect
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import yaml

from syncaudit.errors import UnknownTypeError
from syncaudit.logs import LogReader, open_log
from syncaudit.logs.typesys import TypeRegistry

ROS2_RECORDINGS = {
    # folder: (topic, type) as the shared data README lists them
    "hesai_40p": ("/pandar_packets", "pandar_msgs/msg/PandarScan"),
    "hesai_xt32": ("/pandar_packets", "pandar_msgs/msg/PandarScan"),
    "velodyne_vlp16": ("/velodyne_packets", "velodyne_msgs/msg/VelodyneScan"),
    "velodyne_vlp32": ("/sensing/lidar/front/velodyne_packets", "velodyne_msgs/msg/VelodyneScan"),
}
VLP16_TIMES = [
    1673400471837873222,
    1673400471937957440,
    1673400472038371929,
    1673400472138016708,
]

OUSTER_BAG = "ouster_os1_512x10/512x10_raw.bag"
OUSTER_LIDAR = "/os_node0/lidar_packets"
OUSTER_IMU = "/os_node0/imu_packets"
OUSTER_META = "/os_node0/metadata"
OUSTER_START = 1723828414279578824
OUSTER_END = 1723828414376097122
OUSTER_IMU_TIMES = [
    1723828414280472589,
    1723828414290525473,
    1723828414300662583,
    1723828414310812768,
    1723828414320486133,
    1723828414330488107,
    1723828414340571336,
    1723828414350754812,
    1723828414360705374,
    1723828414370466235,
]


def bag_dir(lidar_data: Path, name: str) -> Path:
    """The rosbag2 directory (holding metadata.yaml) of one recording folder."""
    (meta,) = (lidar_data / name).glob("*/metadata.yaml")
    return meta.parent


def metadata(bag: Path) -> dict[str, Any]:
    """metadata.yaml of a bag, read independently of the reader under test."""
    info: dict[str, Any] = yaml.safe_load((bag / "metadata.yaml").read_text())
    return info["rosbag2_bagfile_information"]


def times(log: LogReader, *args: Any) -> list[int]:
    return [m.log_time_ns for m in log.messages(*args)]


@pytest.mark.parametrize("form", ["directory", "db3"])
@pytest.mark.parametrize("name", sorted(ROS2_RECORDINGS))
def test_ros2_recording_matches_its_metadata(
    lidar_data: Path, name: str, form: str, untouched: Callable[[Path], Path]
) -> None:
    bag = untouched(bag_dir(lidar_data, name))
    meta = metadata(bag)
    path = bag if form == "directory" else bag / meta["relative_file_paths"][0]
    start = meta["starting_time"]["nanoseconds_since_epoch"]
    end = start + meta["duration"]["nanoseconds"]
    expected_topics = {
        t["topic_metadata"]["name"]: (t["topic_metadata"]["type"], t["message_count"])
        for t in meta["topics_with_message_count"]
    }
    assert set(expected_topics) == {ROS2_RECORDINGS[name][0]}  # the README agrees

    with open_log(path) as log:
        summary = log.summary
        assert summary.container == "rosbag2-sqlite3"
        assert summary.path == str(path)
        assert summary.message_count == meta["message_count"]
        assert (summary.start_ns, summary.end_ns) == (start, end)
        assert {n: (t.msgtype, t.count) for n, t in log.topics.items()} == expected_topics
        assert all(t.encoding == "cdr" and not t.has_definition for t in log.topics.values())

        msgs = list(log.messages())
        stamps = [m.log_time_ns for m in msgs]
        assert len(msgs) == meta["message_count"]
        assert stamps == sorted(stamps)
        assert (stamps[0], stamps[-1]) == (start, end)
        assert {(m.topic, m.msgtype, m.encoding) for m in msgs} == {(*ROS2_RECORDINGS[name], "cdr")}
        assert all(isinstance(m.data, bytes | memoryview) and len(m.data) > 0 for m in msgs)
        assert log.warnings == []


def test_vlp16_selection_by_topic_and_time(
    lidar_data: Path, untouched: Callable[[Path], Path]
) -> None:
    bag = untouched(bag_dir(lidar_data, "velodyne_vlp16"))
    with open_log(bag) as log:
        assert times(log) == VLP16_TIMES
        assert times(log, ["/velodyne_packets"]) == VLP16_TIMES
        assert times(log, "/velodyne_packets") == VLP16_TIMES  # a bare string is one topic
        assert times(log, ["/no/such/topic"]) == []
        # start inclusive, stop exclusive, on exact message times
        assert times(log, None, VLP16_TIMES[1], VLP16_TIMES[3]) == VLP16_TIMES[1:3]
        assert times(log, None, VLP16_TIMES[1] + 1) == VLP16_TIMES[2:]
        assert times(log, None, None, VLP16_TIMES[0]) == []
        assert times(log, None, VLP16_TIMES[3], VLP16_TIMES[1]) == []  # crossed range


def test_ouster_ros1_bag(lidar_data: Path, untouched: Callable[[Path], Path]) -> None:
    path = untouched(lidar_data / OUSTER_BAG)
    with open_log(path) as log:
        summary = log.summary
        assert summary.container == "rosbag1"
        assert summary.message_count == 43
        assert (summary.start_ns, summary.end_ns) == (OUSTER_START, OUSTER_END)
        assert {
            n: (t.msgtype, t.encoding, t.count, t.has_definition) for n, t in log.topics.items()
        } == {
            OUSTER_LIDAR: ("ouster_ros/msg/PacketMsg", "ros1", 32, True),
            OUSTER_IMU: ("ouster_ros/msg/PacketMsg", "ros1", 10, True),
            OUSTER_META: ("std_msgs/msg/String", "ros1", 1, True),
        }
        stamps = times(log)
        assert len(stamps) == 43 and stamps == sorted(stamps)
        assert (stamps[0], stamps[-1]) == (OUSTER_START, OUSTER_END)

        assert times(log, [OUSTER_IMU]) == OUSTER_IMU_TIMES
        assert len(times(log, [OUSTER_LIDAR, OUSTER_META])) == 33
        window = (OUSTER_IMU_TIMES[2], OUSTER_IMU_TIMES[7])
        assert times(log, [OUSTER_IMU], *window) == OUSTER_IMU_TIMES[2:7]
        in_window = times(log, None, *window)
        assert len(in_window) == 5 + 16  # 5 IMU and 16 lidar packets in [t2, t7)
        assert all(window[0] <= t < window[1] for t in in_window)
        assert log.warnings == []


def test_ouster_metadata_deserializes_with_the_bags_definition(
    lidar_data: Path, untouched: Callable[[Path], Path]
) -> None:
    with open_log(untouched(lidar_data / OUSTER_BAG)) as log:
        (raw,) = log.messages([OUSTER_META])
        assert raw.encoding == "ros1"
        msg: Any = log.deserialize(raw)
        info = json.loads(msg.data)
        assert info["config_params"]["lidar_mode"] == "512x10"
        assert info["sensor_info"]["prod_line"].startswith("OS-")
        packet: Any = log.deserialize(next(log.messages([OUSTER_LIDAR])))
        assert len(packet.buf) > 0


def _registry_or_skip(msgtype: str) -> None:
    """Skip (naming the missing schema) until another engineer has added it to schemas/."""
    if not TypeRegistry(ros1=False).knows(msgtype):
        package = msgtype.split("/")[0]
        pytest.skip(f"{msgtype} not in schemas/{package} yet (being added by another engineer)")


@pytest.mark.parametrize("name", sorted(ROS2_RECORDINGS))
def test_db3_deserializes_through_project_schemas(
    lidar_data: Path, name: str, untouched: Callable[[Path], Path]
) -> None:
    topic, msgtype = ROS2_RECORDINGS[name]
    _registry_or_skip(msgtype)
    bag = untouched(bag_dir(lidar_data, name))
    with open_log(bag) as log:
        assert not log.topics[topic].has_definition  # so the definition must be schemas/'
        scans: list[Any] = [log.deserialize(m) for m in log.messages()]
    assert len(scans) == metadata(bag)["message_count"]
    for scan in scans:
        assert len(scan.packets) > 10
        if msgtype.startswith("velodyne"):
            assert {len(p.data) for p in scan.packets} == {1206}  # a Velodyne UDP payload
        else:
            sizes = {int(p.size) for p in scan.packets}
            assert len(sizes) == 1 and 0 < sizes.pop() <= len(scan.packets[0].data)
    assert log.warnings == []


def test_unknown_type_on_a_real_db3_raises_unknown_type(
    lidar_data: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Without schemas/ the .db3 types are unknown: a clear UnknownTypeError, not a KeyError."""
    import syncaudit.logs.typesys as typesys

    monkeypatch.setattr(typesys, "project_types", dict)
    with open_log(bag_dir(lidar_data, "velodyne_vlp16")) as log:
        raw = next(log.messages())
        with pytest.raises(UnknownTypeError, match="velodyne_msgs/msg/VelodyneScan") as info:
            log.deserialize(raw)
    assert info.value.exit_code == 4


def test_messages_is_lazy_generator(lidar_data: Path) -> None:
    with open_log(lidar_data / OUSTER_BAG) as log:
        stream = log.messages()
        assert inspect.isgenerator(stream)
        first = next(stream)
        assert first.log_time_ns == OUSTER_START
        stream.close()


@pytest.mark.parametrize("form", ["directory", "db3"])
def test_real_bag_with_blank_metadata_fields(lidar_data: Path, tmp_path: Path, form: str) -> None:
    """Issue 9 item 5: `storage_identifier: ""` and `serialization_format: ""` in the
    metadata (some rosbag2 versions), and an empty format in the .db3 topics table: the bag
    reads as the original does, with warnings naming the quirk, never a dependency's text."""
    import shutil
    import sqlite3

    from typer.testing import CliRunner

    from syncaudit.cli import app

    source = bag_dir(lidar_data, "velodyne_vlp16")
    bag = tmp_path / "bag"
    shutil.copytree(source, bag)
    for path in bag.iterdir():
        path.chmod(0o644)
    doc = yaml.safe_load((bag / "metadata.yaml").read_text())
    info = doc["rosbag2_bagfile_information"]
    info["storage_identifier"] = ""
    for entry in info["topics_with_message_count"]:
        entry["topic_metadata"]["serialization_format"] = ""
    (bag / "metadata.yaml").write_text(yaml.safe_dump(doc))
    (db3,) = bag.glob("*.db3")
    with sqlite3.connect(db3) as db:
        db.execute("UPDATE topics SET serialization_format = ''")
    db.close()
    with open_log(source) as log:
        expected = [(m.topic, m.log_time_ns, bytes(m.data)) for m in log.messages()]
    path = bag if form == "directory" else db3
    with open_log(path) as log:
        assert [(m.topic, m.log_time_ns, bytes(m.data)) for m in log.messages()] == expected
        assert log.topics["/velodyne_packets"].encoding == "cdr"
        codes = sorted(w.code for w in log.warnings)
    if form == "directory":
        assert codes == ["rosbag2-empty-serialization", "rosbag2-storage-inferred"]
    else:
        assert codes == ["rosbag2-empty-serialization"]
    result = CliRunner().invoke(app, ["info", str(path), "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["messages"] == 4 and data["lidars"][0]["model"] == "VLP-16"
    assert "report" not in result.output and "Storage plugin" not in result.output
