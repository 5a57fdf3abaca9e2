"""`audit LOG --lidar-capture CAPTURE`: the LiDAR timing from a capture recorded beside the
cameras' log, and a capture's packets written into a bag give the same `info`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pcap_writer import Datagram, write_capture
from syncaudit.audit.inspect import inspect_log
from syncaudit.audit.run import audit_log
from syncaudit.lidar.hesai import pandar_scan_packets
from syncaudit.lidar.velodyne import velodyne_scan_packets
from syncaudit.logs import open_log
from syncaudit.rig import Rig
from syncaudit.simulate.rig_file import rig_from_truth
from syncaudit.simulate.sync_log import CameraSim, SyncSimConfig, simulate_sync_log
from syncaudit.writers.log_writer import open_writer

CAPTURE_TOPIC = "/pcap/192_168_1_201_2368/velodyne_packets"


def _capture_of(log_path: Path, topic: str, out: Path) -> None:
    """The log's Velodyne or Hesai packets as a capture, each at its driver stamp (the
    host's receive time: what tcpdump beside the driver would have stamped)."""
    datagrams = []
    with open_log(log_path) as log:
        msgtype = log.topics[topic].msgtype
        for msg in log.messages([topic]):
            if msgtype == "velodyne_msgs/msg/VelodyneScan":
                stamps, data = velodyne_scan_packets(msg.data, msg.encoding)
                packets = [p.tobytes() for p in data]
            else:
                stamps, data, sizes = pandar_scan_packets(msg.data, msg.encoding)
                packets = [p[:n].tobytes() for p, n in zip(data, sizes.tolist(), strict=True)]
            for stamp, packet in zip(stamps.tolist(), packets, strict=True):
                datagrams.append(Datagram(int(stamp), packet, 2368))
    out.write_bytes(write_capture(sorted(datagrams, key=lambda d: d.time_ns)))


@pytest.fixture(scope="module")
def simulated(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Rig, Path]:
    folder = tmp_path_factory.mktemp("beside")
    out = folder / "drive.mcap"
    config = SyncSimConfig(
        seed=3,
        lidar_model="VLP-16",
        duration_s=3.0,
        cameras=[CameraSim(name="front", yaw_deg=0.0, delay_error_us=800.0)],
    )
    rig = rig_from_truth(simulate_sync_log(out, config))
    capture = folder / "lidar.pcap"
    _capture_of(out, rig.lidar.topic, capture)
    return out, rig, capture


def test_audit_takes_the_lidar_from_the_capture(simulated: tuple[Path, Rig, Path]) -> None:
    out, rig, capture = simulated
    bag = audit_log(out, rig, jobs=1)
    lidar = rig.lidar.model_copy(update={"topic": CAPTURE_TOPIC})
    capture_rig = rig.model_copy(update={"lidar": lidar})
    beside = audit_log(out, capture_rig, jobs=1, lidar_capture=capture)
    assert beside.lidar.topic == CAPTURE_TOPIC
    assert beside.lidar.packets == bag.lidar.packets
    assert beside.lidar.revolutions == bag.lidar.revolutions
    (a,), (b,) = bag.cameras, beside.cameras
    assert b.sync.frames_paired == a.sync.frames_paired
    assert b.sync.delay_recommended_ns == pytest.approx(a.sync.delay_recommended_ns, abs=1_000)
    assert b.sync.error_mean_ns == pytest.approx(a.sync.error_mean_ns, abs=1_000)
    parallel = audit_log(out, capture_rig, jobs=2, lidar_capture=capture)
    assert parallel.cameras[0].sync.delay_recommended_ns == b.sync.delay_recommended_ns


@pytest.mark.parametrize("model", ["VLP-16", "PandarXT32", "Pandar40P"])
def test_the_capture_written_into_a_bag_gives_the_same_info(tmp_path: Path, model: str) -> None:
    out = tmp_path / "drive.mcap"
    config = SyncSimConfig(seed=5, lidar_model=model, duration_s=1.0)  # type: ignore[arg-type]
    rig = rig_from_truth(simulate_sync_log(out, config))
    capture = tmp_path / "lidar.pcap"
    _capture_of(out, rig.lidar.topic, capture)
    bag = tmp_path / "from_capture.bag"
    with open_log(capture) as log, open_writer(bag, "bag") as writer:
        for topic in log.topics.values():
            writer.add_topic(topic.name, topic.msgtype)
        for msg in log.messages():
            writer.write(msg.topic, msg.log_time_ns, msg.data)
    (from_capture,) = inspect_log(capture, jobs=1).lidars
    (from_bag,) = inspect_log(bag, jobs=1).lidars
    assert from_bag == from_capture
    assert np.isfinite(from_bag.rpm)


def test_the_cli_takes_lidar_capture(simulated: tuple[Path, Rig, Path], tmp_path: Path) -> None:
    import json

    import yaml
    from typer.testing import CliRunner

    from syncaudit.cli import app

    out, rig, capture = simulated
    lidar = rig.lidar.model_copy(update={"topic": CAPTURE_TOPIC})
    rig_file = tmp_path / "capture.rig.yaml"
    rig_file.write_text(
        yaml.safe_dump(rig.model_copy(update={"lidar": lidar}).model_dump(mode="json"))
    )
    args = ["audit", str(out), "--rig", str(rig_file), "--lidar-capture", str(capture), "--json"]
    result = CliRunner().invoke(app, args)
    assert result.exit_code in (0, 10), result.output
    assert json.loads(result.output)["lidar"]["topic"] == CAPTURE_TOPIC
    missing = CliRunner().invoke(app, [*args[:5], str(tmp_path / "none.pcap"), "--json"])
    assert missing.exit_code == 2
