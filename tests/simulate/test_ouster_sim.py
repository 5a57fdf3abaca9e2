"""`simulate sync --lidar ouster`: Ouster packets (LEGACY and RNG profiles) with their
metadata, audited end to end against the simulator's truth."""

from __future__ import annotations

from pathlib import Path

import pytest

from syncaudit.audit.run import audit_log
from syncaudit.lidar import ouster
from syncaudit.logs import open_log
from syncaudit.simulate import ouster_packets
from syncaudit.simulate.rig_file import rig_from_truth
from syncaudit.simulate.sync_log import SyncSimConfig, lidar_model, simulate_sync_log


def test_ouster_is_a_simulated_model() -> None:
    assert lidar_model("ouster") == "OS-1-64"
    with pytest.raises(ValueError, match="600 or 1200 RPM"):
        SyncSimConfig(lidar_model="OS-1-64", rpm=900.0)


@pytest.mark.parametrize("profile", ouster_packets.PROFILES)
def test_an_ouster_rig_is_audited_end_to_end(tmp_path: Path, profile: str) -> None:
    out = tmp_path / f"{profile}.mcap"
    config = SyncSimConfig(seed=11, lidar_model="OS-1-64", ouster_profile=profile, duration_s=3.0)  # type: ignore[arg-type]
    truth = simulate_sync_log(out, config)
    with open_log(out) as log:
        (meta_msg,) = list(log.messages(["/ouster/metadata"]))
        meta = ouster.parse_ouster_metadata(str(log.deserialize(meta_msg).data))  # type: ignore[attr-defined]
    assert (meta.udp_profile_lidar, meta.prod_line) == (profile, "OS-1-64")
    assert meta.packet_bytes == ouster_packets.packet_bytes(profile)
    result = audit_log(out, rig_from_truth(truth), jobs=1)
    lidar = truth["lidar"]
    assert (result.lidar.vendor, result.lidar.model) == ("ouster", "OS-1-64")
    assert result.lidar.packets == lidar["packets_written"]
    assert result.lidar.dropped_packets == lidar["packets_dropped"]
    assert result.lidar.rpm == pytest.approx(lidar["rpm_mean"], rel=0.005)
    assert result.lidar.packets_per_revolution == 64.0  # 1024 columns / 16 per packet
    for cam in result.cameras:
        expected = truth["cameras"][cam.sync.camera]
        assert cam.sync.frames_paired == len(expected["frames"])
        assert cam.sync.error_mean_ns == pytest.approx(expected["error_mean_ns"], abs=2_000)
        assert cam.sync.delay_recommended_ns == pytest.approx(
            expected["ideal_delay_mean_ns"], abs=2_000
        )
