"""`syncaudit simulate sync|calib --config FILE`: one config, the options given over it."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from syncaudit.cli import app

runner = CliRunner()


def _truth(out: Path) -> dict[str, object]:
    loaded: dict[str, object] = json.loads(Path(f"{out}.truth.json").read_text())
    return loaded


def test_a_sync_config_file_gives_the_same_log_as_the_options(tmp_path: Path) -> None:
    """The same settings from a YAML file or from options: byte-identical logs and truths."""
    config = tmp_path / "sim.yaml"
    config.write_text(
        "seed: 7\nduration_s: 1.5\nlidar_model: PandarXT32\npacket_drop_fraction: 0.01\n"
        "controller: {window_frames: 5, min_frames: 5}\n"
    )
    by_file = tmp_path / "file.mcap"
    made = runner.invoke(app, ["simulate", "sync", str(by_file), "--config", str(config)])
    assert made.exit_code == 0, made.output
    toml = tmp_path / "sim.toml"
    toml.write_text('seed = 3\nduration_s = 3.0\nlidar_model = "PandarXT32"\n')
    by_options = tmp_path / "options.mcap"
    made = runner.invoke(
        app,
        [
            "simulate", "sync", str(by_options), "--config", str(toml), "--seed", "7",
            "--duration", "1.5", "--drop-fraction", "0.01", "--controller",
        ],
    )  # fmt: skip
    assert made.exit_code == 0, made.output
    file_truth, options_truth = _truth(by_file), _truth(by_options)
    assert file_truth["config"] == {  # type: ignore[comparison-overlap]
        **options_truth["config"],  # type: ignore[dict-item]
        "controller": file_truth["config"]["controller"],  # type: ignore[index]
    }
    assert file_truth["config"]["controller"]["window_frames"] == 5  # type: ignore[index]
    assert options_truth["config"]["controller"]["window_frames"] == 10  # type: ignore[index]
    assert options_truth["config"]["seed"] == 7  # type: ignore[index]


def test_options_override_the_file_and_the_file_the_defaults(tmp_path: Path) -> None:
    config = tmp_path / "sim.json"
    config.write_text(
        json.dumps(
            {
                "duration_s": 1.0,
                "rpm": 900.0,
                "cameras": [{"name": "solo", "yaw_deg": 10.0}],
                "trigger_packet": "first_after",
            }
        )
    )
    out = tmp_path / "o.mcap"
    made = runner.invoke(
        app,
        [
            "simulate", "sync", str(out), "--config", str(config), "--trigger-packet",
            "containing", "--delay-error-us", "250", "--no-tunnel",
        ],
    )  # fmt: skip
    assert made.exit_code == 0, made.output
    cfg = _truth(out)["config"]
    assert cfg["rpm"] == 900.0 and cfg["duration_s"] == 1.0  # type: ignore[index]
    assert cfg["trigger_packet"] == "containing"  # type: ignore[index]
    assert [c["name"] for c in cfg["cameras"]] == ["solo"]  # type: ignore[index]
    assert cfg["cameras"][0]["delay_error_us"] == 250.0  # type: ignore[index]
    light = cfg["light"]  # type: ignore[index]
    assert light["dark_exposure_us"] == light["bright_exposure_us"]
    assert cfg["controller"] is None  # type: ignore[index]


def test_bad_sync_config_files_and_overrides_are_one_line_errors(tmp_path: Path) -> None:
    out = str(tmp_path / "x.mcap")
    bad = tmp_path / "bad.yaml"
    bad.write_text("duration_s: -1\n")
    made = runner.invoke(app, ["simulate", "sync", out, "--config", str(bad)])
    assert made.exit_code == 6
    assert f"{bad}: duration_s" in made.output and len(made.output.strip().splitlines()) == 1
    bad.write_text("controller: {window_frames: 1}\n")
    made = runner.invoke(app, ["simulate", "sync", out, "--config", str(bad)])
    assert made.exit_code == 6 and "controller.window_frames" in made.output
    bad.write_text("log_format: bag\n")
    made = runner.invoke(app, ["simulate", "sync", out, "--config", str(bad)])
    assert made.exit_code == 6 and "log_format" in made.output
    good = tmp_path / "good.yaml"
    good.write_text("duration_s: 1.0\n")
    made = runner.invoke(app, ["simulate", "sync", out, "--config", str(good), "--stamp", "x"])
    assert made.exit_code == 64 and "--stamp" in made.output
    assert not Path(out).exists()


def test_a_calib_config_file_lists_its_lidars_and_options_override_it(tmp_path: Path) -> None:
    first = tmp_path / "first.mcap"
    made = runner.invoke(
        app, ["simulate", "calib", str(first), "--stops", "2", "--beams", "16", "--seed", "4"]
    )
    assert made.exit_code == 0, made.output
    session = _truth(first)["config"]
    config = tmp_path / "session.json"
    config.write_text(json.dumps({**session, "seed": 9, "n_stops": 3}))  # type: ignore[dict-item]
    again = tmp_path / "again.mcap"
    made = runner.invoke(
        app,
        ["simulate", "calib", str(again), "--config", str(config), "--seed", "4", "--stops", "2"],
    )
    assert made.exit_code == 0, made.output
    assert "16-beam LiDARs session.json" in made.stdout
    assert again.read_bytes() == first.read_bytes()
    made = runner.invoke(
        app, ["simulate", "calib", str(again), "--config", str(config), "--beams", "32"]
    )
    assert made.exit_code == 64 and "--beams" in made.output
    assert len(made.output.strip().splitlines()) == 1
