"""The LiDAR topic guess `info` and `audit` share, on the real Ouster bag (IMU beside LiDAR)."""

from __future__ import annotations

from pathlib import Path

import pytest
from rosbags.rosbag1 import Reader, Writer

from syncaudit.audit.inspect import inspect_log
from syncaudit.audit.run import audit_log
from syncaudit.lidar.packet_topics import guess_lidar_topic, guess_lidar_topics
from syncaudit.logs import open_log

OUSTER_BAG = Path("ouster_os1_512x10") / "512x10_raw.bag"


def test_audit_and_info_pick_the_lidar_packets(lidar_data: Path) -> None:
    bag = lidar_data / OUSTER_BAG
    result = audit_log(bag)  # was: "LiDAR topic /os_node0/imu_packets holds no packets"
    assert result.lidar.topic == "/os_node0/lidar_packets"
    assert result.lidar.packets == 32
    info = inspect_log(bag)
    assert [row.topic for row in info.lidars] == ["/os_node0/lidar_packets"]
    assert any("/os_node0/imu_packets: no LiDAR data packets" in w for w in info.warnings)
    with open_log(bag) as log:
        assert guess_lidar_topic(log) == "/os_node0/lidar_packets"


def _renamed_copy(src: Path, dst: Path, rename: dict[str, str]) -> None:
    """The bag with topics renamed, bytes of every message unchanged."""
    with Reader(src) as reader, Writer(dst) as writer:
        conns = {
            c.id: writer.add_connection(
                rename.get(c.topic, c.topic), c.msgtype, msgdef=c.msgdef.data, md5sum=c.digest
            )
            for c in reader.connections
        }
        for conn, stamp, raw in reader.messages():
            writer.write(conns[conn.id], stamp, raw)


@pytest.mark.parametrize("imu_name", ["/os_node0/aux", "/os_node0/zz_packets"])
def test_imu_packets_told_by_size(lidar_data: Path, tmp_path: Path, imu_name: str) -> None:
    """An IMU packet topic whose name says nothing is set aside by its packet size."""
    bag = tmp_path / "renamed.bag"
    _renamed_copy(lidar_data / OUSTER_BAG, bag, {"/os_node0/imu_packets": imu_name})
    with open_log(bag) as log:
        guess = guess_lidar_topics(log)
    assert guess.topics == ["/os_node0/lidar_packets"]
    assert "48 bytes" in guess.set_aside[imu_name]
    assert "a LiDAR data packet is 8448" in guess.set_aside[imu_name]
    assert audit_log(bag).lidar.topic == "/os_node0/lidar_packets"
