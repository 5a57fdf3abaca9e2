"""Finding logs: folders (ROS 2 bag folders as one log), globs, manifests, vehicle and rig."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from mcap.writer import Writer

from syncaudit.errors import ConfigError
from syncaudit.fleet.inputs import discover, fingerprint, read_manifest
from syncaudit.fleet.policy import parse_policy

from .conftest import SAMPLES


def test_directories_globs_and_bag_folders() -> None:
    policy = parse_policy({}, "p")
    found = discover([str(SAMPLES)], policy)
    names = [Path(j.path).name for j in found.jobs]
    # The .db3 bag folder is one log (not its inner .db3 file); rigs found beside each log.
    assert names == [
        "pandar40p_adaptive.mcap",
        "vlp16_short.bag",
        "vlp16_short_ros2",
        "vlp16_three_cameras.mcap",
    ]
    assert all(j.rig_path == j.path + ".rig.yaml" for j in found.jobs)
    globbed = discover([str(SAMPLES / "vlp16_*"), str(SAMPLES / "vlp16_short.bag")], policy)
    assert [Path(j.path).name for j in globbed.jobs] == [
        "vlp16_short.bag",
        "vlp16_short_ros2",
        "vlp16_three_cameras.mcap",
    ]
    assert discover([str(SAMPLES / "nothing*.mcap")], policy).problems


def test_manifests_and_vehicle_sources(tmp_path: Path) -> None:
    log = SAMPLES / "vlp16_three_cameras.mcap"
    (tmp_path / "m.csv").write_text(
        f"path,vehicle,rig,tags\n{log},car7,{log}.rig.yaml,night;rain\n"
    )
    (job,) = read_manifest(tmp_path / "m.csv")
    assert (job.vehicle, job.rig_path, job.tags) == ("car7", f"{log}.rig.yaml", ("night", "rain"))
    fleet_log = tmp_path / "uploads" / "car12" / log.name
    fleet_log.parent.mkdir(parents=True)
    shutil.copyfile(log, fleet_log)
    (tmp_path / "m.jsonl").write_text(json.dumps({"path": str(fleet_log), "tags": ["a"]}) + "\n")
    policy = parse_policy({"vehicle_pattern": r"/uploads/(?P<vehicle>car\d+)/"}, "p")
    (job,) = discover([str(tmp_path / "m.jsonl")], policy).jobs
    assert job.vehicle == "car12" and job.tags == ("a",)  # from the path pattern
    (tmp_path / "bad.csv").write_text("log,car\nx,y\n")
    with pytest.raises(ConfigError, match="'path' column"):
        read_manifest(tmp_path / "bad.csv")
    (tmp_path / "bad.jsonl").write_text("{not json\n")
    with pytest.raises(ConfigError, match=r"bad.jsonl:1: not JSON"):
        read_manifest(tmp_path / "bad.jsonl")


def test_vehicle_from_mcap_metadata_wins_over_the_pattern(tmp_path: Path) -> None:
    path = tmp_path / "car9" / "drive.mcap"
    path.parent.mkdir()
    with path.open("wb") as handle:
        writer = Writer(handle)
        writer.start()
        writer.add_metadata("vehicle", {"vehicle_id": "VIN123"})
        writer.finish()
    policy = parse_policy({"vehicle_pattern": r"/(?P<vehicle>car\d+)/"}, "p")
    (job,) = discover([str(path)], policy).jobs
    assert job.vehicle == "VIN123"


def test_fingerprint_follows_content(tmp_path: Path) -> None:
    a = tmp_path / "a.mcap"
    data = bytearray((SAMPLES / "vlp16_three_cameras.mcap").read_bytes())
    a.write_bytes(data)
    first = fingerprint(a)
    assert fingerprint(a) == first
    data[-100] ^= 1
    a.write_bytes(data)
    assert fingerprint(a) != first
    bag = fingerprint(SAMPLES / "vlp16_short_ros2")
    assert len(bag) == 32 and bag != first


def test_ros1_bag_vehicle_comes_from_the_path_or_a_manifest_else_a_clear_warning(
    tmp_path: Path,
) -> None:
    """A ROS 1 bag has no metadata record: the pattern or a manifest names its vehicle."""
    bag = tmp_path / "uploads" / "car3" / "drive.bag"
    bag.parent.mkdir(parents=True)
    bag.symlink_to(SAMPLES / "vlp16_short.bag")
    pattern = parse_policy({"vehicle_pattern": r"uploads/(?P<vehicle>car\d+)/"}, "p")
    found = discover([str(bag)], pattern)
    assert [j.vehicle for j in found.jobs] == ["car3"] and found.warnings == []

    elsewhere = tmp_path / "inbox" / "drive.bag"
    elsewhere.parent.mkdir()
    elsewhere.symlink_to(SAMPLES / "vlp16_short.bag")
    found = discover([str(elsewhere)], pattern)
    assert [j.vehicle for j in found.jobs] == [None]
    (warning,) = found.warnings
    assert warning.startswith(f"{elsewhere}: no vehicle id (a ROS 1 bag records none")
    assert "vehicle_pattern 'uploads/(?P<vehicle>car\\d+)/' does not match its path" in warning
    assert "manifest (CSV/JSONL column 'vehicle')" in warning

    (tmp_path / "m.csv").write_text(f"path,vehicle\n{elsewhere},car9\n")
    found = discover([str(tmp_path / "m.csv")], pattern)
    assert [j.vehicle for j in found.jobs] == ["car9"] and found.warnings == []

    # An MCAP without a vehicle metadata record is told apart; a policy that never refers
    # to vehicles asks for none.
    mcap = tmp_path / "inbox" / "drive.mcap"
    mcap.symlink_to(SAMPLES / "vlp16_three_cameras.mcap")
    (warning,) = discover([str(mcap)], pattern).warnings
    assert "no MCAP metadata record with vehicle_id/vehicle" in warning
    assert discover([str(elsewhere), str(mcap)], parse_policy({}, "p")).warnings == []


def test_no_vehicle_warnings_reach_the_summaries_and_stderr(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from syncaudit.cli import app

    bag = tmp_path / "drive.bag"
    bag.symlink_to(SAMPLES / "vlp16_short.bag")
    shutil.copy(SAMPLES / "vlp16_short.bag.rig.yaml", tmp_path / "drive.bag.rig.yaml")
    policy = tmp_path / "policy.yaml"
    policy.write_text(
        "vehicle_pattern: 'uploads/(?P<vehicle>[^/]+)/'\n"
        "defaults: {camera: {error_mean_us: {max: 1.0e+6}, error_var_us2: {max: 1.0e+12}}}\n"
    )
    result = CliRunner().invoke(
        app,
        [
            "gate",
            str(bag),
            "--policy",
            str(policy),
            "--no-db",
            "--summary",
            str(tmp_path / "gate.md"),
            "--json-out",
            str(tmp_path / "gate.json"),
        ],
    )
    assert result.exit_code == 0, result.output
    assert f"warning: {bag}: no vehicle id (a ROS 1 bag records none" in result.output
    summary = json.loads((tmp_path / "gate.json").read_text())
    (warning,) = summary["warnings"]
    assert "ROS 1 bag records none" in warning
    assert "## Warnings" in (tmp_path / "gate.md").read_text()
