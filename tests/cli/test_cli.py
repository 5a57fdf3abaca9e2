"""The command line on real recordings and on bad input: one line, documented exit code."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from marks import write_ours
from slowed_cli import foreground
from syncaudit.cli import app

runner = CliRunner()
VLP16 = Path("velodyne_vlp16") / "1673400471837873222"
REPO = Path(__file__).resolve().parents[2]
SAMPLES = REPO / "sample_logs"
BAG = SAMPLES / "vlp16_short.bag"
BAG_RIG = SAMPLES / "vlp16_short.bag.rig.yaml"


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
    csv = tmp_path / "frames.csv"
    result = runner.invoke(
        app, ["audit", str(lidar_data / VLP16), "--json-out", str(out), "--csv", str(csv)]
    )
    assert result.exit_code == 0, result.output
    data = json.loads(out.read_text())
    assert data["verdict"] == "no cameras"
    assert data["cameras"] == []
    assert any("no camera topics" in m for m in data["missing"])
    header = csv.read_text().splitlines()
    assert len(header) == 1 and header[0].startswith("camera,frame_sequence,")
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
    assert "not valid YAML: line 2" in _one_line_error(
        runner.invoke(app, ["info", log, "--rig", str(broken)]), 6
    )
    assert "hfov_deg" in _one_line_error(
        runner.invoke(app, ["audit", log, "--rig", str(nonsense)]), 6
    )
    assert "lidar.speed: unknown key" in _one_line_error(
        runner.invoke(app, ["audit", log, "--rig", str(unknown)]), 6
    )
    assert "/nope" in _one_line_error(
        runner.invoke(app, ["audit", log, "--rig", str(wrong_topic)]), 7
    )


def test_rig_typo_suggests_the_nearest_key(tmp_path: Path) -> None:
    rig = tmp_path / "typo.yaml"
    rig.write_text(
        "lidar:\n  topic: /velodyne_packets\ncameras:\n  - name: a\n    imag_topic: /a/image\n"
    )
    message = _one_line_error(runner.invoke(app, ["audit", str(BAG), "--rig", str(rig)]), 6)
    assert "cameras.0.imag_topic: unknown key (did you mean 'image_topic'?)" in message


def test_missing_image_topic_is_named(tmp_path: Path) -> None:
    rig = tmp_path / "rig.yaml"
    rig.write_text(BAG_RIG.read_text().replace("/cameras/front/image_raw", "/cameras/nope/image"))
    out = tmp_path / "a.json"
    result = runner.invoke(app, ["audit", str(BAG), "--rig", str(rig), "--json-out", str(out)])
    assert result.exit_code == 0, result.output
    missing = json.loads(out.read_text())["missing"]
    assert "camera front: image topic /cameras/nope/image is not in the log" in missing


def test_help_lists_the_verbs_and_version() -> None:
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0
    for verb in ("info", "audit", "simulate", "calib"):
        assert verb in result.stdout
    version = runner.invoke(app, ["--version"])
    assert version.exit_code == 0 and version.stdout.startswith("syncaudit 0.")
    sub = runner.invoke(app, ["simulate", "--help"])
    assert sub.exit_code == 0 and "sync" in sub.stdout and "calib" in sub.stdout
    calib_help = runner.invoke(app, ["simulate", "calib", "--help"]).stdout
    assert "--beams" in calib_help and "--lidar" not in calib_help
    sync_help = runner.invoke(app, ["simulate", "sync", "--help"]).stdout
    assert "--lidar" in sync_help and "--beams" not in sync_help


@pytest.mark.parametrize(
    ("args", "names"),
    [
        (["audit", "x.mcap", "--bogus"], "--bogus"),
        (["audit", "x.mcap", "--jobs", "0"], "--jobs"),
        (["audit", "x.mcap", "--jobs", "-1"], "--jobs"),
        (["audit", "x.mcap", "--jobs", "two"], "--jobs"),
        (["audit", "x.mcap", "--pairings", "o.txt"], "--pairings"),
        (["simulate", "sync", "o.mcap", "--lidar", "HDL-99"], "--lidar"),
        (["simulate", "sync", "o.mcap", "--format", "zip"], "--format"),
        (["simulate", "sync", "o.mcap", "--format", "db3"], "--format"),
        (["simulate", "sync", "o.mcap", "--duration", "0"], "--duration"),
        (["simulate", "sync", "o.xyz"], "suffix"),
        (["simulate", "calib", "o.mcap", "--stops", "1"], "--stops"),
        (["simulate", "calib", "o.mcap", "--beams", "1"], "--beams"),
        (["simulate", "calib", "o.mcap", "--turning-scans", "2"], "--turning-scans need --scans-"),
        (["calib", "x.mcap", "--topics", "/only/one"], "--topics needs two or more topics"),
        (["simulate", "nonsense"], "nonsense"),
    ],
)
def test_usage_errors_exit_64_naming_the_option(
    tmp_path: Path, args: list[str], names: str
) -> None:
    args = [str(tmp_path / a) if a.startswith(("o.", "x.")) else a for a in args]
    message = _one_line_error(runner.invoke(app, args), 64)
    assert names in message
    assert not list(tmp_path.iterdir())  # nothing written


def test_every_error_class_maps_to_its_documented_code(monkeypatch: pytest.MonkeyPatch) -> None:
    """Rows of the table that need a library failure (4, 70) reached through the CLI's wrapper."""
    import syncaudit.audit.inspect
    from syncaudit import errors

    for cls in (
        errors.LogOpenError,
        errors.LogReadError,
        errors.UnknownTypeError,
        errors.DecodeError,
        errors.ConfigError,
        errors.NoDataError,
        errors.OutputError,
        errors.GateFailedError,
        errors.UsageError,
        RuntimeError,
    ):

        def boom(*_args: object, _cls: type[Exception] = cls, **_kwargs: object) -> None:
            raise _cls("x.mcap: boom")

        monkeypatch.setattr(syncaudit.audit.inspect, "inspect_log", boom)
        result = runner.invoke(app, ["info", "x.mcap"])
        code = getattr(cls, "exit_code", errors.EXIT_INTERNAL)
        message = _one_line_error(result, code)
        assert "x.mcap: boom" in message
        if cls is RuntimeError:
            assert "internal error" in message and "SYNCAUDIT_DEBUG" in message


def test_exit_codes_from_damaged_logs(tmp_path: Path) -> None:
    """Rows 3 and 5 from real damage: a corrupt chunk, packets that are not VLP-16 blocks."""
    import numpy as np

    from syncaudit.writers.log_writer import open_writer

    data = bytearray((SAMPLES / "vlp16_three_cameras.mcap").read_bytes())
    data[len(data) // 2 : len(data) // 2 + 4096] = b"\xff" * 4096
    corrupt = tmp_path / "corrupt.mcap"
    corrupt.write_bytes(bytes(data))
    assert "corrupt" in _one_line_error(runner.invoke(app, ["audit", str(corrupt)]), 3)
    bad = tmp_path / "badpkt.mcap"
    with open_writer(bad, "mcap") as writer:
        writer.add_topic("/velodyne_packets", "velodyne_msgs/msg/VelodyneScan")
        for i in range(3):
            stamp = 10**18 + i * 10**6
            pkt = writer.new_msg(
                "velodyne_msgs/msg/VelodynePacket",
                stamp=writer.time(stamp),
                data=np.full(1206, 0x28, np.uint8),
            )
            scan = writer.new_msg(
                "velodyne_msgs/msg/VelodyneScan", header=writer.header(stamp, "v"), packets=[pkt]
            )
            writer.write_msg("/velodyne_packets", stamp, scan)
    _one_line_error(runner.invoke(app, ["audit", str(bad)]), 5)


def _no_temporaries(folder: Path) -> None:
    left = [
        p.name
        for p in folder.rglob("*")
        if (p.name.startswith(".") and not p.name.endswith(".syncaudit")) or ".tmp" in p.name
    ]  # a CSV's mark (.NAME.syncaudit) is no temporary
    assert not left, left


def test_outputs_all_or_nothing_with_one_overwrite_rule(tmp_path: Path) -> None:
    args = ["audit", str(BAG), "--rig", str(BAG_RIG)]
    pairings = tmp_path / "pairs.mcap"
    assert runner.invoke(app, [*args, "--pairings", str(pairings)]).exit_code == 0
    before = pairings.read_bytes()
    new_json, new_csv = tmp_path / "new.json", tmp_path / "new.csv"
    refused = runner.invoke(
        app,
        [*args, "--json-out", str(new_json), "--csv", str(new_csv), "--pairings", str(pairings)],
    )
    message = _one_line_error(refused, 8)
    assert "pairs.mcap: exists (pass --overwrite to replace it)" in message
    assert not new_json.exists() and not new_csv.exists()  # checked before any work
    assert pairings.read_bytes() == before
    for option, name in (("--json-out", "a.json"), ("--csv", "a.csv"), ("--html", "a.html")):
        target = tmp_path / name
        target.write_text("previous")  # the user's own file: never replaced, whatever the flags
        message = _one_line_error(
            runner.invoke(app, [*args, option, str(target), "--overwrite"]), 8
        )
        assert "did not write" in message and "--overwrite" not in message
        assert target.read_text() == "previous"
        previous = write_ours(target)  # an earlier output of the tool: --overwrite replaces it
        message = _one_line_error(runner.invoke(app, [*args, option, str(target)]), 8)
        assert "--overwrite" in message and target.read_text() == previous
    replaced = runner.invoke(
        app,
        [*args, "--overwrite", "--json-out", str(tmp_path / "a.json"), "--pairings", str(pairings)],
    )
    assert replaced.exit_code == 0, replaced.output
    assert json.loads((tmp_path / "a.json").read_text())["cameras"]
    missing_dir = tmp_path / "nope" / "r.html"
    assert "does not exist" in _one_line_error(
        runner.invoke(app, [*args, "--html", str(missing_dir)]), 8
    )
    _no_temporaries(tmp_path)


def test_an_existing_directory_is_never_replaced(tmp_path: Path) -> None:
    folder = tmp_path / "X.mcap"
    (folder / "keep").mkdir(parents=True)
    (folder / "keep" / "precious.txt").write_text("mine")
    args = ["audit", str(BAG), "--rig", str(BAG_RIG), "--overwrite"]
    for option in ("--pairings", "--json-out"):
        message = _one_line_error(runner.invoke(app, [*args, option, str(folder)]), 8)
        assert "not replacing it" in message
    assert (folder / "keep" / "precious.txt").read_text() == "mine"
    # The tool's own bag folder is replaced with --overwrite (and only with it).
    bag = tmp_path / "pairs"
    assert runner.invoke(app, [*args, "--pairings", str(bag)]).exit_code == 0
    assert (bag / "metadata.yaml").is_file() and (bag / "pairs.db3").is_file()
    assert runner.invoke(app, [*args, "--pairings", str(bag)]).exit_code == 0
    _no_temporaries(tmp_path)


def test_an_input_is_never_an_output(tmp_path: Path) -> None:
    rig = tmp_path / "rig.yaml"
    rig.write_text(BAG_RIG.read_text())
    before = rig.read_bytes()
    message = _one_line_error(
        runner.invoke(
            app, ["audit", str(BAG), "--rig", str(rig), "--json-out", str(rig), "--overwrite"]
        ),
        64,  # a usage error, before any work
    )
    assert "input" in message and rig.read_bytes() == before


def test_outputs_to_devices_write_through() -> None:
    before = os.stat("/dev/null")
    result = runner.invoke(
        app, ["audit", str(BAG), "--rig", str(BAG_RIG), "--json-out", "/dev/null"]
    )
    assert result.exit_code == 0, result.output
    after = os.stat("/dev/null")
    assert (after.st_mode, after.st_rdev) == (before.st_mode, before.st_rdev)


def test_simulate_sync_writes_log_truth_and_rig_then_audits(tmp_path: Path) -> None:
    out = tmp_path / "sim.mcap"
    made = runner.invoke(
        app, ["simulate", "sync", str(out), "--duration", "1", "--seed", "3", "--lidar", "xt32"]
    )
    assert made.exit_code == 0, made.output
    assert f"wrote {out} (PandarXT32" in made.stdout
    for suffix in ("", ".truth.json", ".rig.yaml"):
        assert Path(f"{out}{suffix}").is_file()
    audited = runner.invoke(app, ["audit", str(out), "--rig", f"{out}.rig.yaml", "--json"])
    assert audited.exit_code == 0, audited.output
    assert len(json.loads(audited.stdout)["cameras"]) == 3
    before = out.read_bytes()
    again = runner.invoke(app, ["simulate", "sync", str(out), "--duration", "1"])
    assert "--overwrite" in _one_line_error(again, 8)
    assert out.read_bytes() == before
    _no_temporaries(tmp_path)


@pytest.mark.parametrize(
    ("convention", "offset"), [("first_after", 0), ("containing", 2), ("containing", -1)]
)
def test_simulate_trigger_packet_conventions_audit_to_the_truth(
    tmp_path: Path, convention: str, offset: int
) -> None:
    """The simulator's trigger-packet options, through the CLI: the audit's recommended
    delay stays within 20 us of the truth whichever packet the triggers name."""
    out = tmp_path / "sim.mcap"
    made = runner.invoke(
        app,
        [
            "simulate", "sync", str(out), "--lidar", "VLP-32C", "--duration", "2",
            "--trigger-packet", convention, "--trigger-packet-offset", str(offset),
        ],
    )  # fmt: skip
    assert made.exit_code == 0, made.output
    truth = json.loads(Path(f"{out}.truth.json").read_text())
    audited = runner.invoke(app, ["audit", str(out), "--rig", f"{out}.rig.yaml", "--json"])
    assert audited.exit_code == 0, audited.output
    for cam in json.loads(audited.stdout)["cameras"]:
        ideal_us = truth["cameras"][cam["camera"]]["ideal_delay_mean_ns"] / 1e3
        assert abs(cam["delay_recommended_us"] - ideal_us) < 20.0
        assert cam["packet_phase_source"] == "trigger packet"
    bad = runner.invoke(
        app, ["simulate", "sync", str(tmp_path / "x.mcap"), "--trigger-packet", "x"]
    )
    assert "--trigger-packet" in _one_line_error(bad, 64)


def test_simulate_db3_names_the_bag_folder_sanely(tmp_path: Path) -> None:
    made = runner.invoke(app, ["simulate", "sync", str(tmp_path / "drive.db3"), "--duration", "1"])
    assert made.exit_code == 0, made.output
    assert (tmp_path / "drive" / "drive.db3").is_file()
    assert (tmp_path / "drive.truth.json").is_file() and (tmp_path / "drive.rig.yaml").is_file()
    assert not (tmp_path / "drive.db3").exists()
    pairs = runner.invoke(
        app, ["audit", str(BAG), "--rig", str(BAG_RIG), "--pairings", str(tmp_path / "p.db3")]
    )
    assert pairs.exit_code == 0, pairs.output
    assert sorted(p.name for p in (tmp_path / "p").iterdir()) == ["metadata.yaml", "p.db3"]


def test_simulate_calib_writes_session(tmp_path: Path) -> None:
    # A long folder name: piped output must not wrap at 80 columns (issue 11).
    folder = tmp_path / ("deep" * 20)
    folder.mkdir()
    out = folder / "calib.mcap"
    made = runner.invoke(app, ["simulate", "calib", str(out), "--stops", "3", "--seed", "1"])
    assert made.exit_code == 0, made.output
    assert "3 stops" in made.stdout and Path(f"{out}.truth.json").is_file()
    assert made.stdout.count("\n") == 1


def _run_cli(*args: str, **kwargs: object) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "syncaudit", *args],
        capture_output=True,
        text=True,
        check=False,
        **kwargs,  # type: ignore[arg-type]
    )


def test_console_script_exit_codes_and_flushed_output(tmp_path: Path) -> None:
    """The entry point skips interpreter teardown: its exit code and output must survive."""
    sample = SAMPLES / "pandar40p_adaptive.mcap"
    rig = sample.with_name(sample.name + ".rig.yaml")
    ok = _run_cli("audit", str(sample), "--rig", str(rig), "--json")
    assert ok.returncode == 0, ok.stderr
    assert json.loads(ok.stdout)["cameras"]  # the whole JSON document arrived
    gate = _run_cli("audit", str(sample), "--rig", str(rig), "--gate")
    assert gate.returncode == (0 if json.loads(ok.stdout)["verdict"] == "pass" else 10)
    missing = _run_cli("audit", str(tmp_path / "none.mcap"))
    assert missing.returncode == 2
    assert missing.stderr.strip().startswith("error:") and missing.stderr.count("\n") == 1
    usage = _run_cli()
    assert usage.returncode == 64 and "audit" in usage.stdout
    bad_option = _run_cli("audit", "x.mcap", "--jobs", "0")
    assert bad_option.returncode == 64 and "--jobs" in bad_option.stderr
    script = Path(sys.executable).with_name("syncaudit")
    if script.is_file():
        version = subprocess.run([script, "--version"], capture_output=True, text=True, check=False)
        assert version.returncode == 0 and version.stdout.startswith("syncaudit ")


def test_piped_output_is_complete_and_head_is_fine(tmp_path: Path) -> None:
    """Not a terminal: no "…" truncation, no hard wrap; a reader that leaves is no error."""
    sample = SAMPLES / "vlp16_three_cameras.mcap"
    env = {**os.environ, "COLUMNS": "40"}
    info = _run_cli("info", str(sample), env=env)
    assert info.returncode == 0, info.stderr
    assert "…" not in info.stdout
    assert "/cameras/rear_right/image_raw" in info.stdout  # topic names whole, on one line
    audit = _run_cli("audit", str(sample), "--rig", f"{sample}.rig.yaml", env=env)
    assert "…" not in audit.stdout
    lidar_line = next(line for line in audit.stdout.splitlines() if line.startswith("LiDAR "))
    assert "revolutions" in lidar_line and "t1 p50/p99" in lidar_line  # one unwrapped line
    piped = subprocess.run(
        f"{sys.executable} -m syncaudit info {sample} | head -1; exit ${{PIPESTATUS[0]}}",
        shell=True,
        executable="/bin/bash",
        capture_output=True,
        text=True,
        check=False,
    )
    assert piped.returncode == 0, piped.stderr
    assert piped.stderr == ""


@pytest.mark.parametrize("signum", [15, 2])
def test_a_signal_leaves_no_partial_output(tmp_path: Path, signum: int) -> None:
    """SIGTERM or SIGINT while simulating: exit 130, no temporary, the previous output intact."""
    import time

    out = tmp_path / "long.mcap"
    # The previous output is one of ours (only those --overwrite may replace).
    subprocess.run(
        [sys.executable, "-m", "syncaudit", "simulate", "sync", str(out), "--duration", "1"],
        check=True,
        capture_output=True,
    )
    previous = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    process = subprocess.Popen(
        foreground(
            [
                sys.executable,
                "-m",
                "syncaudit",
                "simulate",
                "sync",
                str(out),
                "--duration",
                "120",
                "--overwrite",
            ]
        ),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    # Wait for the write phase (its temporary) however loaded the machine: the arrays of a
    # 120 s log take seconds to compute first, and the writing takes longer still.
    deadline = time.monotonic() + 120
    while (
        time.monotonic() < deadline
        and process.poll() is None
        and not any(tmp_path.glob(".syncaudit-*"))
    ):
        time.sleep(0.05)
    time.sleep(0.3)
    assert process.poll() is None, "the simulation ended before it could be interrupted"
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=30)
    assert process.returncode == 130, stderr
    assert "interrupted" in stderr and "Traceback" not in stderr
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == previous


def test_audit_keeps_lidar_warnings_and_the_clock_offset_sign(
    lidar_data: Path, tmp_path: Path
) -> None:
    """The VLP-32 recording is FOV-cropped: info and audit (JSON, HTML) both say so."""
    log = lidar_data / "velodyne_vlp32" / "1713492677464078412"
    if not log.exists():
        pytest.skip("velodyne_vlp32 recording absent")
    info = runner.invoke(app, ["info", str(log), "--json"])
    assert info.exit_code == 0, info.output
    crop = [w for w in json.loads(info.stdout)["warnings"] if "FOV-cropped" in w]
    assert crop
    out, html = tmp_path / "a.json", tmp_path / "a.html"
    audited = runner.invoke(app, ["audit", str(log), "--json-out", str(out), "--html", str(html)])
    assert audited.exit_code == 0, audited.output
    assert crop[0] in json.loads(out.read_text())["warnings"]
    page = html.read_text()
    assert "FOV-cropped" in page
    assert "host - sensor +51.6" in page


def test_csv_header_is_the_frame_tables_columns(tmp_path: Path) -> None:
    """The header written without cameras is the analysis' own frame table columns."""
    from syncaudit.writers.frames_csv import FRAME_TABLE_COLUMNS

    csv = tmp_path / "f.csv"
    result = runner.invoke(app, ["audit", str(BAG), "--rig", str(BAG_RIG), "--csv", str(csv)])
    assert result.exit_code == 0, result.output
    assert csv.read_text().splitlines()[0].split(",") == list(FRAME_TABLE_COLUMNS)


def test_help_imports_nothing_heavy() -> None:
    """`syncaudit --help` stays fast: no numpy, pandas, pydantic, rich, yaml or simulator."""
    code = (
        "import sys; from syncaudit.cli import app; "
        "heavy = {'numpy', 'pandas', 'pydantic', 'rich', 'yaml', 'syncaudit.simulate.sync_log'}; "
        "print(sorted(heavy & set(sys.modules)))"
    )
    loaded = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.strip()
    assert loaded == "[]"
