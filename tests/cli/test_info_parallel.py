"""`info` reads the LiDAR and shared camera topics as `audit` does (chunk-parallel where
the log allows): the same report with one process or several, and the LiDAR counted as
the audit counts it (an Ouster packet message is one scan message, not a batch)."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import pytest

from mcap_copy import copy_mcap
from syncaudit.audit.inspect import inspect_log
from syncaudit.audit.run import audit_log
from syncaudit.logs import open_log
from syncaudit.logs import parallel as parallel_read
from syncaudit.logs.unit_readers import group_units
from syncaudit.simulate.sync_log import CameraSim, SyncSimConfig, simulate_sync_log

REPO = Path(__file__).resolve().parents[2]
OUSTER_BAG = REPO.parent / "shared" / "data" / "lidar" / "ouster_os1_512x10" / "512x10_raw.bag"


@pytest.mark.parametrize("log_format", ["mcap", "bag"])
def test_info_is_the_same_with_one_process_or_several(
    tmp_path: Path, log_format: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / f"sim.{log_format}"
    cameras = [CameraSim(name="front", yaw_deg=0.0), CameraSim(name="left", yaw_deg=100.0)]
    simulate_sync_log(
        out,
        SyncSimConfig(
            cameras=cameras,
            duration_s=3.0,
            seed=4,
            log_format=log_format,
            exposure_messages=("flir_meta",),
            shared_topics=("image", "meta", "trigger"),
            camera_field=False,
        ),
    )
    if log_format == "mcap":  # the simulator writes one chunk: copy into small ones
        out = copy_mcap(out, tmp_path / "log.mcap", chunk_size=50_000)
    monkeypatch.setattr(
        parallel_read, "GROUP_BYTES", 200_000
    )  # several tasks: jobs=2 uses the pool
    with open_log(out) as log:
        units = log.read_units(frozenset(log.topics))
        assert units is not None and len(group_units(units, parallel_read.GROUP_BYTES)) > 2
    serial = inspect_log(out, jobs=1)
    parallel = inspect_log(out, jobs=2)
    assert asdict(parallel) == asdict(serial)
    assert serial.shared_topics and serial.lidars[0].packets > 1000
    assert serial.lidars[0].scans == audit_log(out, jobs=2).lidar.scans


@pytest.mark.skipif(not OUSTER_BAG.exists(), reason=f"real data not present: {OUSTER_BAG}")
def test_info_counts_ouster_packet_messages_as_the_audit_does() -> None:
    """Real OS1-512x10 bag: 32 single-packet messages (before, `info` said 1 "scan": the
    batch its serial reader decoded them in)."""
    report = inspect_log(OUSTER_BAG, jobs=1)
    (lidar,) = report.lidars
    assert (lidar.scans, lidar.packets) == (32, 32)
