"""The command line on real recordings and on bad input: one line, documented exit code."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from syncaudit.cli import app

runner = CliRunner()
VLP16 = Path("velodyne_vlp16") / "1673400471837873222"
REPO = Path(__file__).resolve().parents[2]


def test_info_json_on_real_velodyne(lidar_data: Path) -> None:
    result = runner.invoke(app, ["info", str(lidar_data / VLP16), "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["container"] == "rosbag2-sqlite3"
    assert data["messages"] == 4
    (lidar,) = data["lidars"]
    assert (lidar["vendor"], lidar["model"]) == ("velodyne", "VLP-16")
    assert lidar["clock_synchronised"] is False
    assert lidar["clock_offset_s"] == pytest.approx(1531.18, abs=0.05)
    assert "no camera topic found" in " ".join(data["warnings"])


def test_info_table_on_ouster_bag(lidar_data: Path) -> None:
    result = runner.invoke(app, ["info", str(lidar_data / "ouster_os1_512x10" / "512x10_raw.bag")])
    assert result.exit_code == 0, result.output
    assert "OS-0-128" in result.stdout
    assert "imu_packets: no LiDAR data packets" in result.stdout


def test_audit_lidar_only_log_says_what_is_missing(lidar_data: Path, tmp_path: Path) -> None:
    out = tmp_path / "audit.json"
    result = runner.invoke(app, ["audit", str(lidar_data / VLP16), "--json-out", str(out)])
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["verdict"] == "no cameras"
    assert data["cameras"] == []
    assert any("no camera topics" in m for m in data["missing"])
    gated = runner.invoke(app, ["audit", str(lidar_data / VLP16), "--gate"])
    assert gated.exit_code == 10


def _one_line_error(result: object, code: int) -> str:
    assert result.exit_code == code, result.output
    stderr = result.stderr
    assert stderr.startswith("error: ")
    assert stderr.count("\n") == 1, stderr
    assert "Traceback" not in result.output
    return str(stderr)


def test_bad_inputs(tmp_path: Path) -> None:
    empty_dir = tmp_path / "bag"
    empty_dir.mkdir()
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    noise = tmp_path / "noise.bag"
    noise.write_bytes(os.urandom(4096))
    cases = [
        (tmp_path / "missing.mcap", 2, "no such file"),
        (empty_dir, 2, "no metadata.yaml"),
        (empty, 2, "file is empty"),
        (noise, 2, "unknown log format"),
    ]
    for path, code, text in cases:
        before = path.read_bytes() if path.is_file() else None
        message = _one_line_error(runner.invoke(app, ["info", str(path)]), code)
        assert text in message
        if before is not None:
            assert path.read_bytes() == before


def test_bad_rig_files(lidar_data: Path, tmp_path: Path) -> None:
    log = str(lidar_data / VLP16)
    broken = tmp_path / "broken.yaml"
    broken.write_text("lidar: [1, 2\n")
    nonsense = tmp_path / "nonsense.yaml"
    nonsense.write_text(
        "lidar:\n  topic: /velodyne_packets\ncameras:\n  - name: a\n    hfov_deg: -3\n"
    )
    unknown = tmp_path / "unknown.toml"
    unknown.write_text('[lidar]\ntopic = "/velodyne_packets"\nspeed = 3\n')
    wrong_topic = tmp_path / "wrong.yaml"
    wrong_topic.write_text("lidar:\n  topic: /nope\n")
    assert "not valid yaml" in _one_line_error(
        runner.invoke(app, ["info", log, "--rig", str(broken)]), 6
    )
    assert "hfov_deg" in _one_line_error(
        runner.invoke(app, ["audit", log, "--rig", str(nonsense)]), 6
    )
    assert "speed" in _one_line_error(runner.invoke(app, ["audit", log, "--rig", str(unknown)]), 6)
    assert "/nope" in _one_line_error(
        runner.invoke(app, ["audit", log, "--rig", str(wrong_topic)]), 7
    )


def test_help_lists_the_verbs() -> None:
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0
    for verb in ("info", "audit"):
        assert verb in result.stdout


def test_outputs_never_clobbered_and_unwritable_paths(lidar_data: Path, tmp_path: Path) -> None:
    sample = Path(__file__).resolve().parents[2] / "sample_logs" / "vlp16_short.bag"
    args = ["audit", str(sample), "--rig", f"{sample}.rig.yaml"]
    pairings = tmp_path / "pairs.mcap"
    assert runner.invoke(app, [*args, "--pairings", str(pairings)]).exit_code == 0
    before = pairings.read_bytes()
    assert "exists" in _one_line_error(runner.invoke(app, [*args, "--pairings", str(pairings)]), 8)
    assert pairings.read_bytes() == before
    ok = runner.invoke(app, [*args, "--pairings", str(pairings), "--overwrite"])
    assert ok.exit_code == 0
    missing_dir = tmp_path / "nope" / "r.html"
    assert "cannot write" in _one_line_error(
        runner.invoke(app, [*args, "--html", str(missing_dir)]), 8
    )
    assert not list(tmp_path.glob(".*tmp"))


def test_outputs_to_devices_write_through() -> None:
    sample = Path(__file__).resolve().parents[2] / "sample_logs" / "vlp16_short.bag"
    before = os.stat("/dev/null")
    result = runner.invoke(
        app, ["audit", str(sample), "--rig", f"{sample}.rig.yaml", "--json-out", "/dev/null"]
    )
    assert result.exit_code == 0, result.output
    after = os.stat("/dev/null")
    assert (after.st_mode, after.st_rdev) == (before.st_mode, before.st_rdev)


def test_simulate_writes_log_truth_and_rig_then_audits(tmp_path: Path) -> None:
    out = tmp_path / "sim.mcap"
    made = runner.invoke(app, ["simulate", str(out), "--duration", "1", "--seed", "3"])
    assert made.exit_code == 0, made.output
    assert f"wrote {out}" in made.stdout
    for suffix in ("", ".truth.json", ".rig.yaml"):
        assert Path(f"{out}{suffix}").is_file()
    audited = runner.invoke(app, ["audit", str(out), "--rig", f"{out}.rig.yaml", "--json"])
    assert audited.exit_code == 0, audited.output
    assert len(json.loads(audited.stdout)["cameras"]) == 3
    again = runner.invoke(app, ["simulate", str(out), "--duration", "1"])
    assert "exists" in _one_line_error(again, 6)
    assert "suffix" in _one_line_error(runner.invoke(app, ["simulate", str(tmp_path / "x.xyz")]), 6)


def test_simulate_calib_writes_session(tmp_path: Path) -> None:
    out = tmp_path / "calib.mcap"
    made = runner.invoke(app, ["simulate", str(out), "--calib", "--stops", "3", "--seed", "1"])
    assert made.exit_code == 0, made.output
    assert "3 stops" in made.stdout and Path(f"{out}.truth.json").is_file()
    assert "n_stops" in _one_line_error(
        runner.invoke(app, ["simulate", str(tmp_path / "c2.mcap"), "--calib", "--stops", "1"]), 6
    )


def test_console_script_exit_codes_and_flushed_output(tmp_path: Path) -> None:
    """The entry point skips interpreter teardown: its exit code and output must survive."""
    sample = REPO / "sample_logs" / "pandar40p_adaptive.mcap"
    rig = sample.with_name(sample.name + ".rig.yaml")
    command = [sys.executable, "-m", "syncaudit.cli"]
    ok = subprocess.run(
        [*command, "audit", str(sample), "--rig", str(rig), "--json"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert ok.returncode == 0, ok.stderr
    assert json.loads(ok.stdout)["cameras"]  # the whole JSON document arrived
    gate = subprocess.run(
        [*command, "audit", str(sample), "--rig", str(rig), "--gate"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert gate.returncode == (0 if json.loads(ok.stdout)["verdict"] == "pass" else 10)
    missing = subprocess.run(
        [*command, "audit", str(tmp_path / "none.mcap")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert missing.returncode == 2
    assert missing.stderr.strip().startswith("error:") and missing.stderr.count("\n") == 1
    usage = subprocess.run(command, capture_output=True, text=True, check=False)
    assert usage.returncode == 2 and "audit" in usage.stdout
