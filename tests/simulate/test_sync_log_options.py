"""Simulator options: the benchmark's (a VLS-128, six cameras, JPEG-sized images), and
shared camera topics and header-stamp conventions through `simulate sync`."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import zstandard

from syncaudit.lidar.velodyne import (
    decode_velodyne,
    velodyne_firing_offsets_ns,
    velodyne_scan_packets,
)
from syncaudit.lidar.velodyne_encode import velodyne_revolution_schedule
from syncaudit.logs import open_log
from syncaudit.simulate.sync_log import CameraSim, SyncSimConfig, simulate_sync_log

SIX = [CameraSim(name=f"cam{i}", yaw_deg=60.0 * i) for i in range(6)]


@pytest.fixture(scope="module")
def vls128(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    out = tmp_path_factory.mktemp("sim") / "vls128.mcap"
    config = SyncSimConfig(
        seed=3,
        duration_s=1.0,
        lidar_model="VLS-128",
        rpm_drift_frac=0.0,
        packet_drop_fraction=0.0,
        zero_azimuth_deg=305.0,
        cameras=SIX,
    )
    return out, simulate_sync_log(out, config)


def _decoded(out: Path, topic: str) -> Any:
    stamps, datas = [], []
    with open_log(out) as log:
        for raw in log.messages([topic]):
            s, d = velodyne_scan_packets(raw.data, raw.encoding)
            stamps.append(s)
            datas.append(np.array(d))
    return decode_velodyne(np.concatenate(datas), np.concatenate(stamps))


def test_vls128_packets_follow_the_velodyne_schedule(vls128: tuple[Path, dict[str, Any]]) -> None:
    out, truth = vls128
    lidar = truth["lidar"]
    timing = _decoded(out, lidar["topic"])
    assert timing.model == "VLS-128"
    assert timing.n_packets == lidar["packets_written"]
    assert np.abs(np.diff(timing.sensor_time_ns) - lidar["packet_period_ns"]).max() <= 1_000
    az = np.rint(timing.block_azimuth_deg * 100).astype(np.int64)
    # The four banks of a firing sequence share the azimuth sampled when it starts.
    for bank in (1, 2, 3):
        np.testing.assert_array_equal(az[:, bank::4], az[:, 0::4])
    # Within one 0.01 deg quantum of the velodyne module's own schedule (the simulated
    # packet stamps are whole microseconds, the schedule's exact).
    config = truth["config"]
    first_firing = int(velodyne_firing_offsets_ns("VLS-128", False).min())
    w0 = config["rpm"] * 6.0 / 1e9
    sched = velodyne_revolution_schedule(
        "VLS-128",
        config["rpm"],
        config["start_time_ns"] + first_firing,
        start_azimuth_deg=config["start_azimuth_deg"] + w0 * first_firing,
        n_packets=timing.n_packets,
    )
    expected = np.rint(sched.block_azimuth_deg * 100).astype(np.int64)
    assert np.abs((az - expected + 18_000) % 36_000 - 18_000).max() <= 1


def test_vls128_truth_is_exact(vls128: tuple[Path, dict[str, Any]]) -> None:
    """Azimuths interpolated at their sample times give the truth's crossings."""
    out, truth = vls128
    lidar = truth["lidar"]
    timing = _decoded(out, lidar["topic"])
    sample = velodyne_firing_offsets_ns("VLS-128", False)[:, 0]
    sample = sample[(np.arange(12) // 4) * 4]  # sequence start, manual's timing
    t = (timing.sensor_time_ns[:, None] + sample[None, :]).reshape(-1).astype(np.float64)
    az_q = np.rint(timing.block_azimuth_deg * 100).astype(np.int64).reshape(-1)
    unwrapped = np.concatenate(([az_q[0]], az_q[0] + np.cumsum(np.diff(az_q) % 36_000)))
    zero_q = round(lidar["zero_azimuth_deg"] * 100)
    first_turn = (unwrapped[0] - zero_q) // 36_000 + 1
    targets = zero_q + 36_000 * (first_turn + np.arange(lidar["revolutions"]))
    cross = np.interp(targets.astype(np.float64), unwrapped.astype(np.float64), t)
    assert np.abs(cross - np.array(lidar["zero_crossing_ns"])).max() < 3_000
    assert sorted(truth["cameras"]) == [f"cam{i}" for i in range(6)]
    thetas = [cam["theta_deg"] for cam in truth["cameras"].values()]
    assert min(thetas) == pytest.approx(55.0)


def test_jpeg_sized_compressed_images(tmp_path: Path) -> None:
    out = tmp_path / "jpeg.mcap"
    size = 65_536
    config = SyncSimConfig(
        duration_s=1.0,
        image_kind="compressed",
        image_bytes=size,
        cameras=SIX[:2],
    )
    truth = simulate_sync_log(out, config)
    cam = truth["cameras"]["cam1"]
    with open_log(out) as log:
        images = [log.deserialize(m) for m in log.messages([cam["topics"]["image"]])]
    assert len(images) == cam["frames_count"]
    stamps = [f["image_stamp_ns"] for f in cam["frames"]]
    payloads = []
    for image, stamp in zip(images, stamps, strict=True):
        data = bytes(image.data)
        assert image.format == "jpeg"
        assert image.header.stamp.sec * 1_000_000_000 + image.header.stamp.nanosec == stamp
        assert len(data) == size
        assert data[:4] == b"\xff\xd8\xff\xe0" and data[6:11] == b"JFIF\x00"
        assert data[-2:] == b"\xff\xd9"
        assert b"\xff" not in data[20:-2]  # no false markers in the entropy-coded part
        payloads.append(data)
    assert len(set(payloads)) == len(payloads)
    # Incompressible, like a real JPEG: zstd gains under 1 %.
    assert len(zstandard.ZstdCompressor().compress(payloads[0])) > 0.99 * size
    # Same seed, same bytes.
    again = tmp_path / "again.mcap"
    simulate_sync_log(again, config)
    assert again.read_bytes() == out.read_bytes()


def test_defaults_and_validation() -> None:
    assert SyncSimConfig().image_bytes is None
    with pytest.raises(ValueError, match="image_bytes"):
        SyncSimConfig(image_bytes=300_000)
    with pytest.raises(ValueError):
        SyncSimConfig(image_kind="compressed", image_bytes=10)
    assert SyncSimConfig(lidar_model="VLS-128").vendor == "velodyne"


def test_cli_shared_topics_and_stamp_audit_to_the_truth(tmp_path: Path) -> None:
    """`simulate sync` writes one image/meta/trigger topic for all cameras, told apart only by
    header.frame_id, with exposure-end stamps; its rig audits each camera to the truth."""
    from typer.testing import CliRunner

    from syncaudit.cli import app

    runner = CliRunner()
    out = tmp_path / "shared.mcap"
    made = runner.invoke(
        app,
        [
            "simulate", "sync", str(out), "--duration", "3", "--seed", "4",
            "--shared-topics", "image,meta,trigger", "--exposure-messages", "flir_meta",
            "--no-camera-field", "--stamp", "exposure_end",
        ],
    )  # fmt: skip
    assert made.exit_code == 0, made.output
    truth = json.loads(Path(f"{out}.truth.json").read_text())
    assert {c["topics"]["image"] for c in truth["cameras"].values()} == {"/cameras/image_raw"}
    audited = runner.invoke(app, ["audit", str(out), "--rig", f"{out}.rig.yaml", "--json"])
    assert audited.exit_code == 0, audited.output
    for cam in json.loads(audited.stdout)["cameras"]:
        t = truth["cameras"][cam["camera"]]
        assert cam["frames_paired"] == len(t["frames"])
        assert abs(cam["error_mean_us"] - t["error_mean_ns"] / 1e3) < 5.0
    bad = runner.invoke(app, ["simulate", "sync", str(tmp_path / "x.mcap"), "--stamp", "late"])
    assert bad.exit_code == 64 and "--stamp" in bad.output


def test_extra_lidar_packets_and_an_unchanged_audit(tmp_path: Path) -> None:
    """A second LiDAR's scans land on its own topic with its own model and packet count,
    and leave the trigger LiDAR, the cameras and the rig's audit exactly as without it."""
    from syncaudit.audit.run import audit_log
    from syncaudit.rig import load_rig
    from syncaudit.simulate.rig_file import rig_from_truth
    from syncaudit.simulate.sync_log import ExtraLidarSim

    base = {"seed": 4, "duration_s": 2.0, "cameras": SIX[:2], "zero_azimuth_deg": 305.0}
    extra = ExtraLidarSim(model="VLP-32C", topic="/rear/velodyne_packets", frame_id="rear")
    plain_truth = simulate_sync_log(tmp_path / "plain.mcap", SyncSimConfig(**base))
    both_truth = simulate_sync_log(
        tmp_path / "both.mcap", SyncSimConfig(**base, extra_lidars=[extra])
    )
    facts = both_truth["extra_lidars"][0]
    assert facts["model"] == "VLP-32C" and facts["scans"] > 10
    timing = _decoded(tmp_path / "both.mcap", "/rear/velodyne_packets")
    assert timing.model == "VLP-32C" and timing.n_packets == facts["packets_written"]
    assert both_truth["cameras"]["cam0"]["frames"] == plain_truth["cameras"]["cam0"]["frames"]
    rig_file = tmp_path / "rig.yaml"
    rig_file.write_text(json.dumps(rig_from_truth(plain_truth).model_dump(mode="json")))
    rig = load_rig(rig_file)
    plain = audit_log(tmp_path / "plain.mcap", rig, jobs=1).to_dict()
    both = audit_log(tmp_path / "both.mcap", rig, jobs=1).to_dict()
    assert both["cameras"] == plain["cameras"]
    with pytest.raises(ValueError, match="unique"):
        SyncSimConfig(**base, extra_lidars=[extra, extra])
    with pytest.raises(ValueError, match="Velodyne or Hesai"):
        ExtraLidarSim(model="OS-1-64", topic="/o", frame_id="o")
