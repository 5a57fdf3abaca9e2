"""The simulator writes the newer Hesai models; the decode/audit path measures them right."""

from __future__ import annotations

from pathlib import Path

import pytest

from syncaudit.audit import audit_log
from syncaudit.lidar.scan import scan_lidar
from syncaudit.logs import open_log
from syncaudit.simulate import LidarModel
from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log


@pytest.mark.parametrize(
    ("model", "per_rev"),
    [("PandarXT32M", 333.33), ("Pandar128E4X", 900.0)],  # single return, 600 RPM
)
def test_simulated_model_scans_and_audits(
    tmp_path: Path, model: LidarModel, per_rev: float
) -> None:
    out = tmp_path / "sim.mcap"
    truth = simulate_sync_log(
        out, SyncSimConfig(lidar_model=model, duration_s=0.5, packet_drop_fraction=0.0)
    )
    topic = truth["lidar"]["topic"]
    with open_log(out) as log:
        scan = scan_lidar(log, topic)
    assert (scan.vendor, scan.model) == ("hesai", model)
    assert scan.rpm == pytest.approx(600.0, rel=0.01)
    assert scan.packets_per_revolution == pytest.approx(per_rev, abs=1)
    assert scan.dropped_packets == 0
    assert scan.declared_rpm == pytest.approx(600.0)
    assert scan.warnings == []
    result = audit_log(out, jobs=1)
    assert result.lidar.model == model
    assert not any("RPM" in w for w in result.warnings)
