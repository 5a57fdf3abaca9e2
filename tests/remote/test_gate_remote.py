"""`syncaudit gate` on an http:// prefix served by a real loopback Range server."""

from __future__ import annotations

import json
from pathlib import Path

from syncaudit.fleet.gate import GateOptions, run_gate
from syncaudit.fleet.policy import parse_policy

from .conftest import ServerState

REPO = Path(__file__).resolve().parents[2]
SAMPLES = REPO / "sample_logs"
POLICY = {
    "vehicle_pattern": r"uploads/(?P<vehicle>[^/]+)/",
    "defaults": {"lidar": {"rpm": {"min": 500, "max": 700}}},
}


def _uploads(root: Path) -> None:
    for vehicle, name in (("car1", "vlp16_three_cameras.mcap"), ("car2", "vlp16_short.bag")):
        folder = root / "uploads" / vehicle
        folder.mkdir(parents=True)
        (folder / name).symlink_to(SAMPLES / name)
    bag = root / "uploads" / "car3" / "vlp16_short_ros2"
    bag.mkdir(parents=True)  # a real folder: the local walk does not follow folder links
    for file in (SAMPLES / "vlp16_short_ros2").iterdir():
        (bag / file.name).symlink_to(file)


def test_gate_on_an_http_prefix_matches_the_local_run(
    http_root: tuple[str, ServerState], tmp_path: Path
) -> None:
    base, state = http_root
    _uploads(state.root)
    policy = parse_policy(POLICY, "policy.yaml")
    remote = run_gate(
        [f"{base}/uploads/"],
        policy,
        GateOptions(db=None, json_out=tmp_path / "remote.json", jobs=2),
    )
    local = run_gate(
        [str(state.root / "uploads")],
        policy,
        GateOptions(db=None, json_out=tmp_path / "local.json", jobs=2),
    )
    got = json.loads((tmp_path / "remote.json").read_text())["logs"]
    want = json.loads((tmp_path / "local.json").read_text())["logs"]
    assert [log["path"] for log in got] == [
        f"{base}/uploads/car1/vlp16_three_cameras.mcap",
        f"{base}/uploads/car2/vlp16_short.bag",
        f"{base}/uploads/car3/vlp16_short_ros2",
    ]
    assert [log.error for log in remote.logs] == [None, None, None]
    assert [log.verdict for log in remote.logs] == [log.verdict for log in local.logs]
    assert [log["checks"] for log in got] == [log["checks"] for log in want]
    assert [log["vehicle"] for log in got] == ["car1", "car2", "car3"]
    mcap = got[0]["remote_read"]
    assert (
        mcap["ranged"]
        and mcap["size_bytes"] == (SAMPLES / "vlp16_three_cameras.mcap").stat().st_size
    )
    assert mcap["fetched_bytes"] <= mcap["size_bytes"]
    assert got[1]["remote_read"]["ranged"] is True  # ROS 1 bag: its chunks by ranges too
    assert got[2]["remote_read"]["ranged"] is False  # ROS 2 bag folder: downloaded whole


def test_slow_server_hits_the_per_log_timeout(
    http_root: tuple[str, ServerState], tmp_path: Path
) -> None:
    base, state = http_root
    (state.root / "slow.mcap").symlink_to(SAMPLES / "vlp16_three_cameras.mcap")
    state.delay_s = 30
    run = run_gate(
        [f"{base}/slow.mcap"],
        parse_policy(POLICY, "policy.yaml"),
        GateOptions(db=None, jobs=1, timeout_s=1.5),
    )
    assert run.exit_code == 3
    (log,) = run.logs
    assert log.verdict == "error" and log.error is not None and "timed out" in log.error


def test_gate_takes_the_rig_beside_a_remote_log_as_beside_a_local_one(
    http_root: tuple[str, ServerState], tmp_path: Path
) -> None:
    """`LOG.rig.yaml` beside an uploaded log is its rig by URL as by path: the same checks,
    the same rig fingerprint, and a different result from the guess."""
    base, state = http_root
    _uploads(state.root)
    name = "vlp16_three_cameras.mcap"
    rig = state.root / "uploads" / "car1" / f"{name}.rig.yaml"
    rig.write_text((SAMPLES / f"{name}.rig.yaml").read_text())
    policy = parse_policy(POLICY, "policy.yaml")
    outs = {}
    for where, inputs in (("remote", f"{base}/uploads/car1/"), ("local", str(rig.parent))):
        run_gate([inputs], policy, GateOptions(db=None, json_out=tmp_path / where, jobs=1))
        outs[where] = json.loads((tmp_path / where).read_text())["logs"]
    (remote,), (local,) = outs["remote"], outs["local"]
    assert remote["rig_fingerprint"] is not None
    assert remote["rig_fingerprint"] == local["rig_fingerprint"]
    assert remote["checks"] == local["checks"]
    assert f"/uploads/car1/{name}.rig.yaml" in " ".join(state.requests)
    rig.unlink()
    run_gate([f"{base}/uploads/car1/"], policy, GateOptions(db=None, json_out=tmp_path / "g"))
    (guessed,) = json.loads((tmp_path / "g").read_text())["logs"]
    assert guessed["rig_fingerprint"] is None and guessed["checks"] != remote["checks"]
