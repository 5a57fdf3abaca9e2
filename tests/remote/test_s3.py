"""s3:// through s3fs against moto's standalone S3-compatible server on loopback.

Credentials and endpoint come from the usual AWS environment variables (what a real
deployment sets); nothing is passed on the command line or stored.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest

from syncaudit.fleet.gate import GateOptions, run_gate
from syncaudit.fleet.policy import parse_policy

moto_server = pytest.importorskip("moto.server")
pytest.importorskip("s3fs")
boto3 = pytest.importorskip("boto3")

SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"
SECRET = "not-a-real-secret-0123456789"


@pytest.fixture()
def s3_endpoint(monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    """moto's S3 server on 127.0.0.1 with a bucket holding two sample logs."""
    server = moto_server.ThreadedMotoServer(ip_address="127.0.0.1", port=0, verbose=False)
    server.start()
    host, port = server.get_host_and_port()
    endpoint = f"http://{host}:{port}"
    monkeypatch.setenv("AWS_ACCESS_KEY_ID", "testing")
    monkeypatch.setenv("AWS_SECRET_ACCESS_KEY", SECRET)
    monkeypatch.setenv("AWS_DEFAULT_REGION", "us-east-1")
    monkeypatch.setenv("AWS_ENDPOINT_URL", endpoint)
    try:
        client = boto3.client("s3", endpoint_url=endpoint)
        client.create_bucket(Bucket="fleet")
        for key, name in (
            ("uploads/car1/a.mcap", "vlp16_three_cameras.mcap"),
            ("uploads/car2/b.bag", "vlp16_short.bag"),
        ):
            client.upload_file(str(SAMPLES / name), "fleet", key)
        yield endpoint
    finally:
        server.stop()


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
