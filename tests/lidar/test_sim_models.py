"""The simulator writes the newer Hesai models; the decode/audit path measures them right."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from syncaudit.audit.run import audit_log
from syncaudit.lidar.hesai import HESAI_LAYOUTS, pandar_scan_packets
from syncaudit.lidar.scan import scan_lidar
from syncaudit.logs import open_log
from syncaudit.simulate import LidarModel
from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log


@pytest.mark.parametrize(
    ("model", "per_rev", "header_returns", "mode"),
    # 600 RPM; the XT32M as on the real capture: header Return Number 3 (the sensor's
    # maximum), tail 0x3C (dual), 3 firings x 2 returns per packet; OT128 single return.
    [("PandarXT32M", 666.67, 3, 0x3C), ("Pandar128E4X", 900.0, 1, 0x37)],
)
def test_simulated_model_scans_and_audits(
    tmp_path: Path, model: LidarModel, per_rev: float, header_returns: int, mode: int
) -> None:
    out = tmp_path / "sim.mcap"
    truth = simulate_sync_log(out, SyncSimConfig(lidar_model=model, duration_s=1.0))["lidar"]
    with open_log(out) as log:
        raw = next(iter(log.messages([truth["topic"]])))
        _, data, _ = pandar_scan_packets(raw.data, raw.encoding)
        scan = scan_lidar(log, truth["topic"])
    layout = HESAI_LAYOUTS[model]
    assert (data[:, 10] == header_returns).all()
    tail = layout.body_end + layout.body_trailer_bytes + layout.fs_bytes_if_flagged
    assert (data[:, tail + layout.tail_return_mode] == mode).all()
    assert (scan.vendor, scan.model) == ("hesai", model)
    assert scan.rpm == pytest.approx(truth["rpm_mean"], rel=1e-3)
    assert scan.packets_per_revolution == pytest.approx(per_rev, abs=2)
    assert scan.dropped_packets == truth["packets_dropped"] > 0
    assert scan.packets == truth["packets_written"]  # delivered ones (drops not counted)
    assert scan.dual_return == (model == "PandarXT32M")
    assert scan.declared_rpm == pytest.approx(600.0)
    assert scan.warnings == []
    result = audit_log(out, jobs=1)
    assert result.lidar.model == model
    assert result.lidar.dropped_packets == truth["packets_dropped"]
    assert not any("RPM" in w for w in result.warnings)
    assert np.isfinite(result.lidar.rpm)
