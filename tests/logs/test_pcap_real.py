"""The six real captures in ../shared/data/pcap: what their README states, read by `info`."""

from __future__ import annotations

from pathlib import Path

import pytest

from syncaudit.audit.inspect import InfoReport, inspect_log
from syncaudit.logs import open_log

OS0 = "OS-0-128-U1_v2.3.0_1024x10.pcap"
OS1_32 = "OS-1-32-G_v2.1.1_1024x10.pcap"
OS1_FUSA = "OS-1-128_767798045_1024x10_20230712_120049.pcap"
VLP16 = "rlu_velodyne_vlp16.pcap"
HDL32 = "rlu_hdl32_example.pcap"
MONTEREY = "veloview_hdl32_monterey_first_100_packets.pcap"


def _info(pcap_data: Path, name: str) -> InfoReport:
    return inspect_log(pcap_data / name, jobs=1)


def _count(pcap_data: Path, name: str, suffix: str) -> int:
    with open_log(pcap_data / name) as log:
        (topic,) = [t for t in log.topics.values() if t.name.endswith(suffix)]
        assert topic.count is not None
        return topic.count


def _rpm_close(rpm: float, expected: float) -> bool:
    return abs(rpm - expected) <= 0.005 * expected


def test_os0_128_rng15(pcap_data: Path) -> None:
    report = _info(pcap_data, OS0)
    (lidar,) = report.lidars
    assert (lidar.vendor, lidar.model, lidar.packets) == ("ouster", "OS-0-128", 64)
    assert _rpm_close(lidar.rpm, 600.0)
    assert lidar.revolutions == 1  # one complete frame: 64 packets x 16 columns = 1024
    assert _count(pcap_data, OS0, "imu_packets") == 10


def test_os1_32_legacy(pcap_data: Path) -> None:
    report = _info(pcap_data, OS1_32)
    (lidar,) = report.lidars
    assert (lidar.vendor, lidar.model, lidar.packets) == ("ouster", "OS-1-32-G", 64)
    assert _rpm_close(lidar.rpm, 600.0)
    assert lidar.revolutions == 1


def test_os1_128_fusa_dual(pcap_data: Path) -> None:
    report = _info(pcap_data, OS1_FUSA)
    (lidar,) = report.lidars
    assert (lidar.model, lidar.packets, lidar.dual_return) == ("OS-1-128", 8, True)
    assert "Ouster metadata: timestamp_mode TIME_FROM_INTERNAL_OSC" in report.warnings
    assert _rpm_close(lidar.rpm, 600.0)


def test_vlp16_with_the_hdl32e_id_is_a_vlp16(pcap_data: Path) -> None:
    report = _info(pcap_data, VLP16)
    (lidar,) = report.lidars
    assert (lidar.vendor, lidar.model, lidar.packets) == ("velodyne", "VLP-16", 84)
    assert _rpm_close(lidar.rpm, 599.0)
    assert any("product byte says HDL-32E" in w for w in report.warnings)
    assert _count(pcap_data, VLP16, "position_packets") == 16
    assert any("PPS absent x16; NMEA fix no $GPRMC x16" in w for w in report.warnings)


def test_hdl32e_example(pcap_data: Path) -> None:
    report = _info(pcap_data, HDL32)
    (lidar,) = report.lidars
    assert (lidar.model, lidar.packets, lidar.dropped_packets) == ("HDL-32E", 876, 0)
    assert _rpm_close(lidar.rpm, 703.0)
    assert 154 <= lidar.packets_per_revolution <= 155
    # 5 complete revolutions (whole turns swept; a partial one at either end).
    assert lidar.revolutions == 5
    assert not any("product byte" in w for w in report.warnings)
    assert _count(pcap_data, HDL32, "position_packets") == 100
    position = "/pcap/192_168_1_201_8308/position_packets: PPS absent x100; NMEA fix valid x100"
    assert position in report.warnings


def test_monterey_hdl32e_wrap_block(pcap_data: Path) -> None:
    report = _info(pcap_data, MONTEREY)
    (lidar,) = report.lidars
    assert (lidar.model, lidar.packets) == ("HDL-32E", 2702)
    assert _rpm_close(lidar.rpm, 706.0)
    # VeloView: 19 frames, 17 complete and 2 partial: 17 whole turns swept.
    assert lidar.revolutions == 17
    assert lidar.azimuth_36000_blocks == 1
    assert _count(pcap_data, MONTEREY, "position_packets") == 299


def test_monterey_wrap_block_is_packet_857_block_4(pcap_data: Path) -> None:
    import numpy as np

    from syncaudit.lidar import velodyne

    with open_log(pcap_data / MONTEREY) as log:
        (topic,) = [t for t in log.topics if t.endswith("velodyne_packets")]
        parts = [velodyne.velodyne_scan_packets(m.data, m.encoding) for m in log.messages(topic)]
    data = np.concatenate([p[1] for p in parts])
    azimuth = data[:, :1200].reshape(-1, 12, 100)[:, :, 2:4].copy().view("<u2")[..., 0]
    assert [tuple(x) for x in np.argwhere(azimuth == 36000)] == [(857, 4)]
    assert azimuth[857, 3:6].tolist() == [35979, 36000, 18]


@pytest.mark.parametrize("name", [OS0, OS1_32, OS1_FUSA, VLP16, HDL32, MONTEREY])
def test_the_same_packets_in_a_bag_give_the_same_info(
    pcap_data: Path, tmp_path: Path, name: str
) -> None:
    from syncaudit.writers.log_writer import open_writer

    bag = tmp_path / "same.bag"
    with open_log(pcap_data / name) as log, open_writer(bag, "bag") as writer:
        for topic in log.topics.values():
            writer.add_topic(topic.name, topic.msgtype)
        for msg in log.messages():
            writer.write(msg.topic, msg.log_time_ns, msg.data)
    capture, written = _info(pcap_data, name), inspect_log(bag, jobs=1)
    assert [repr(r) for r in written.lidars] == [repr(r) for r in capture.lidars]  # NaN too
    assert [(t.name, t.count) for t in written.topics] == [
        (t.name, t.count) for t in capture.topics
    ]
    # The capture reader also reads the position packets' PPS / NMEA state (the bag's
    # position topic is one more topic): the rest is the same.
    shown = [w for w in capture.warnings if "PPS " not in w and "timestamp_mode" not in w]
    assert sorted(written.warnings) == sorted(shown)


def test_ouster_without_metadata_says_how_to_give_it(pcap_data: Path, tmp_path: Path) -> None:
    import shutil

    from syncaudit.errors import NoDataError

    copy = tmp_path / "bare.pcap"
    shutil.copyfile(pcap_data / OS0, copy)
    report = inspect_log(copy, jobs=1, partial=True)
    assert isinstance(report.error, str) and "metadata" in report.error
    assert any("--lidar-metadata FILE" in w for w in report.warnings)
    given = inspect_log(copy, jobs=1, lidar_metadata=pcap_data / OS0.replace(".pcap", ".json"))
    assert given.lidars[0].model == "OS-0-128"
    with pytest.raises(NoDataError):
        inspect_log(copy, jobs=1)


def test_audit_of_a_capture_is_its_lidar_side(pcap_data: Path) -> None:
    from syncaudit.audit.run import audit_log

    result = audit_log(pcap_data / MONTEREY, jobs=1)
    assert (result.lidar.model, result.lidar.packets, result.cameras) == ("HDL-32E", 2702, [])
    assert any("1 block read azimuth 36000" in w for w in result.warnings)
