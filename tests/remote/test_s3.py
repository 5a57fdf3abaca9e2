"""s3:// through s3fs against moto's standalone S3-compatible server on loopback.

Credentials and endpoint come from the usual AWS environment variables (what a real
deployment sets); nothing is passed on the command line or stored.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from syncaudit.fleet.gate import GateOptions, run_gate
from syncaudit.fleet.policy import parse_policy

from .conftest import SECRET, fetched

moto_server = pytest.importorskip("moto.server")
pytest.importorskip("s3fs")
boto3 = pytest.importorskip("boto3")

SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"


def test_gate_on_an_s3_prefix(s3_endpoint: str, tmp_path: Path) -> None:
    policy = parse_policy({"vehicle_pattern": r"uploads/(?P<vehicle>[^/]+)/"}, "policy.yaml")
    out = tmp_path / "gate.json"
    db = tmp_path / "fleet.duckdb"
    run = run_gate(["s3://fleet/uploads/"], policy, GateOptions(db=db, json_out=out, jobs=2))
    logs = json.loads(out.read_text())["logs"]
    assert [log["path"] for log in logs] == [
        "s3://fleet/uploads/car1/a.mcap",
        "s3://fleet/uploads/car2/b.bag",
    ]
    assert [log.error for log in run.logs] == [None, None]
    assert [log["vehicle"] for log in logs] == ["car1", "car2"]
    assert logs[0]["remote_read"]["ranged"] is True
    assert (
        logs[0]["remote_read"]["size_bytes"]
        == (SAMPLES / "vlp16_three_cameras.mcap").stat().st_size
    )
    # No credential anywhere in what was written.
    assert SECRET not in out.read_text()
    assert SECRET.encode() not in db.read_bytes()
    # Unchanged objects (same ETag and size) are skipped on the next run.
    again = run_gate(["s3://fleet/uploads/"], policy, GateOptions(db=db, jobs=2))
    assert all(log.skipped for log in again.logs)


def test_a_ros2_mcap_bag_prefix_on_s3_is_read_by_ranges(s3_endpoint: str, tmp_path: Path) -> None:
    from logs.test_mcap_bag import _to_bag
    from syncaudit.audit.run import audit_log
    from syncaudit.logs import open_log
    from syncaudit.logs.ros2.remote import RemoteMcapBag
    from syncaudit.simulate.rig_file import rig_from_truth
    from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log

    bare = tmp_path / "log.mcap"
    truth = simulate_sync_log(bare, SyncSimConfig(seed=5, duration_s=2.0, lidar_model="VLP-16"))
    folder = tmp_path / "bag"
    _to_bag(bare, folder, 2)
    client = boto3.client("s3", endpoint_url=s3_endpoint)
    for file in folder.iterdir():
        client.upload_file(str(file), "fleet", f"bags/car3/bag/{file.name}")
    rig = rig_from_truth(truth)
    url = "s3://fleet/bags/car3/bag"
    with open_log(url) as log:
        assert isinstance(log, RemoteMcapBag) and len(log._logs) == 2
    with open_log(url) as log:  # its fetch statistics cover the audit's own open
        remote = audit_log(url, rig, jobs=2).to_dict()
        stats = fetched(log)
    local = audit_log(folder, rig, jobs=2).to_dict()
    remote.pop("path"), local.pop("path")
    assert remote == local
    assert stats["ranged"] and stats["fetched_bytes"] <= stats["size_bytes"] + (64 << 10)
    assert stats["size_bytes"] == sum(f.stat().st_size for f in folder.glob("*.mcap"))
