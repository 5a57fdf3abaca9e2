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


def test_a_cloud_only_log_is_audited_with_a_guessed_rig(tmp_path: Path) -> None:
    out = tmp_path / "clouds.mcap"
    config = SyncSimConfig(duration_s=3.0, cloud_convention="ouster", lidar_packets=False)
    simulate_sync_log(out, config)
    result = audit_log(out, jobs=1)
    assert result.lidar.topic == "/points"
    assert result.lidar.revolutions >= 28
    assert any("PointCloud2 with per-point t" in g for g in result.guessed)
