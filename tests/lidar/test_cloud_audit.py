"""One simulated drive written as packets and as clouds audits alike, per camera."""

from __future__ import annotations

from pathlib import Path

import pytest

from syncaudit.audit.run import audit_log
from syncaudit.simulate.cloud_writer import CLOUD_CONVENTIONS, CloudConvention
from syncaudit.simulate.rig_file import rig_from_truth
from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log


@pytest.mark.parametrize("convention", CLOUD_CONVENTIONS)
def test_packets_and_clouds_of_one_drive_audit_alike(
    tmp_path: Path, convention: CloudConvention
) -> None:
    out = tmp_path / "drive.mcap"
    config = SyncSimConfig(duration_s=3.0, cloud_convention=convention)
    rig = rig_from_truth(simulate_sync_log(out, config))
    packets = audit_log(out, rig, jobs=1).to_dict()
    cloud_rig = rig.model_copy(update={"lidar": rig.lidar.model_copy(update={"topic": "/points"})})
    clouds = audit_log(out, cloud_rig, jobs=1).to_dict()
    assert clouds["lidar"]["revolutions"] == packets["lidar"]["revolutions"]
    assert clouds["lidar"]["rpm"] == pytest.approx(packets["lidar"]["rpm"], rel=1e-4)
    assert clouds["verdict"] == packets["verdict"]
    assert len(clouds["cameras"]) == len(packets["cameras"]) == 3
    for p, c in zip(packets["cameras"], clouds["cameras"], strict=True):
        assert c["frames_paired"] == p["frames_paired"] > 20
        assert c["unpaired"] == p["unpaired"]
        assert c["error_mean_us"] == pytest.approx(p["error_mean_us"], abs=2.0)


def test_a_cloud_only_log_is_audited_with_a_guessed_rig_as_its_packets(tmp_path: Path) -> None:
    """No rig: the cloud topic is guessed by its fields and its +X measured (0: no azimuth
    field), so the cameras are placed and judged as from the packets of the same drive."""
    clouds_log, packets_log = tmp_path / "clouds.mcap", tmp_path / "packets.mcap"
    config = SyncSimConfig(duration_s=3.0, cloud_convention="ouster", lidar_packets=False)
    simulate_sync_log(clouds_log, config)
    simulate_sync_log(packets_log, SyncSimConfig(duration_s=3.0))
    clouds = audit_log(clouds_log, jobs=1)
    packets = audit_log(packets_log, jobs=1).to_dict()
    assert clouds.lidar.topic == "/points"
    assert any("PointCloud2 with per-point t; its +X at azimuth 0" in g for g in clouds.guessed)
    result = clouds.to_dict()
    assert result["verdict"] == packets["verdict"]
    assert len(result["cameras"]) == len(packets["cameras"]) == 3
    for p, c in zip(packets["cameras"], result["cameras"], strict=True):
        assert c["frames_paired"] == p["frames_paired"]
        assert c["error_mean_us"] == pytest.approx(p["error_mean_us"], abs=2.0)


def test_info_reports_a_cloud_only_lidar_as_for_packets(tmp_path: Path) -> None:
    from syncaudit.audit.inspect import inspect_log

    packets_log, clouds_log = tmp_path / "p.mcap", tmp_path / "c.mcap"
    simulate_sync_log(packets_log, SyncSimConfig(duration_s=3.0))
    simulate_sync_log(
        clouds_log, SyncSimConfig(duration_s=3.0, cloud_convention="velodyne", lidar_packets=False)
    )
    (p,) = inspect_log(packets_log, jobs=1).lidars
    (c,) = inspect_log(clouds_log, jobs=1).lidars
    assert c.topic == "/points"
    assert c.revolutions == p.revolutions
    assert c.rpm == pytest.approx(p.rpm, rel=1e-4)
    assert c.clock_synchronised is p.clock_synchronised is True


def test_info_checks_clouds_against_the_packets(tmp_path: Path) -> None:
    from syncaudit.audit.inspect import inspect_log

    out = tmp_path / "both.mcap"
    simulate_sync_log(out, SyncSimConfig(duration_s=3.0, cloud_convention="hesai"))
    report = inspect_log(out, jobs=1)
    assert [row.topic for row in report.lidars] == ["/velodyne_packets", "/points"]
    (note,) = [w for w in report.warnings if w.startswith("/points: per-point times")]
    assert " agree (" in note


def test_info_reports_clouds_whose_times_disagree_with_the_packets() -> None:
    from syncaudit.audit.cloud_info import cloud_agreement
    from syncaudit.columns.lidar import LidarScan

    def scan(topic: str, zeros: list[int]) -> LidarScan:
        import numpy as np

        from syncaudit.lidar.revolutions import RevolutionTracker

        columns = RevolutionTracker().finish()
        revs = type(columns)(
            **{
                **{f: getattr(columns, f) for f in columns.__dataclass_fields__},
                "zero_crossing_sensor_ns": np.array(zeros, dtype=np.int64),
            }
        )
        return LidarScan(
            topic=topic,
            vendor="",
            model="",
            scans=0,
            packets=0,
            return_modes=(),
            dual_return=False,
            revolutions=revs,
            clock=None,
            omega_blocks_deg_s=float("nan"),
            cropped_sector=None,
            outlier_blocks=0,
        )

    zeros = [k * 100_000_000 for k in range(1, 6)]
    ok = cloud_agreement(scan("/c", zeros), scan("/p", zeros))
    assert ok.agrees and ok.paired == 5
    late = cloud_agreement(scan("/c", [z + 1_327_000 for z in zeros]), scan("/p", zeros))
    assert not late.agrees
    assert "DISAGREE" in late.note() and "+1327.0 us" in late.note()


def test_clouds_read_in_parallel_audit_as_serially(tmp_path: Path) -> None:
    out = tmp_path / "clouds.mcap"
    config = SyncSimConfig(duration_s=3.0, cloud_convention="nebula", lidar_packets=False)
    simulate_sync_log(out, config)
    serial = audit_log(out, jobs=1).to_dict()
    parallel = audit_log(out, jobs=2).to_dict()
    assert parallel == serial
    assert serial["lidar"]["revolutions"] >= 28


def test_the_starter_rig_of_a_cloud_only_log_names_the_cloud_and_its_x_axis(
    tmp_path: Path,
) -> None:
    from syncaudit.audit.rig_guess import starter_rig_yaml
    from syncaudit.rig import load_rig

    out = tmp_path / "clouds.mcap"
    simulate_sync_log(
        out, SyncSimConfig(duration_s=3.0, cloud_convention="nebula", lidar_packets=False)
    )
    text = starter_rig_yaml(out)
    assert "a PointCloud2 with per-point times" in text
    assert "azimuth_of_x_axis_deg: 0  # measured from the first cloud's points" in text
    rig_file = tmp_path / "rig.yaml"
    rig_file.write_text(text)
    rig = load_rig(rig_file)
    assert rig.lidar.topic == "/points"
    assert rig.lidar.azimuth_of_x_axis_deg == 0.0
    result = audit_log(out, rig, jobs=1)
    assert [c.sync.frames_paired for c in result.cameras] == [29, 29, 29]
