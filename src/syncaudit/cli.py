"""The `syncaudit` command line: thin verbs over the library API."""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, TypeVar, get_args

import typer
from rich.console import Console

from syncaudit.errors import OutputError, SyncauditError
from syncaudit.fleet.cli import register as register_fleet
from syncaudit.simulate import LidarModel

app = typer.Typer(
    name="syncaudit",
    help="Audit LiDAR-camera synchronisation and LiDAR extrinsics in MCAP, ROS 2 and ROS 1 logs.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
stdout = Console()
stderr = Console(stderr=True, soft_wrap=True)

EXIT_INTERNAL = 70
T = TypeVar("T")

RigOption = Annotated[
    Path | None,
    typer.Option(
        "--rig", help="Rig file (YAML/TOML/JSON); topics and cameras are guessed without it."
    ),
]
JsonFlag = Annotated[
    bool, typer.Option("--json", help="Print the result as JSON instead of tables.")
]


def _run(job: Callable[[], T]) -> T:
    """Run a command body: known errors become one line on stderr and their exit code."""
    try:
        return job()
    except SyncauditError as exc:
        stderr.print(f"[red]error:[/] {exc}", highlight=False)
        raise typer.Exit(exc.exit_code) from None
    except KeyboardInterrupt:
        raise typer.Exit(130) from None
    except OSError as exc:  # outputs: exists, no permission, disk full
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        reason = exc.strerror or str(exc)
        stderr.print(f"[red]error:[/] {where}{reason}", highlight=False)
        raise typer.Exit(OutputError.exit_code) from None
    except Exception as exc:
        if os.environ.get("SYNCAUDIT_DEBUG"):
            raise
        stderr.print(
            f"[red]internal error:[/] {type(exc).__name__}: {exc} "
            "(set SYNCAUDIT_DEBUG=1 for a traceback and please report it)",
            highlight=False,
        )
        raise typer.Exit(EXIT_INTERNAL) from None


def _print_json(data: Any) -> None:
    sys.stdout.write(json.dumps(data, indent=2, allow_nan=False) + "\n")


@app.command()
def info(
    log: Annotated[
        Path, typer.Argument(help="MCAP file, ROS 2 bag (dir/.db3/.mcap) or ROS 1 .bag.")
    ],
    rig: RigOption = None,
    as_json: JsonFlag = False,
) -> None:
    """Summarise a log: topics, each LiDAR (measured RPM, drops, clock) and each camera."""
    from syncaudit.inspect_log import inspect_log
    from syncaudit.report.console import render_info
    from syncaudit.rig import load_rig

    def job() -> None:
        report = inspect_log(log, load_rig(rig) if rig else None)
        if as_json:
            _print_json(report.to_dict())
        else:
            render_info(report, stdout)

    _run(job)


@app.command()
def audit(
    log: Annotated[
        Path, typer.Argument(help="MCAP file, ROS 2 bag (dir/.db3/.mcap) or ROS 1 .bag.")
    ],
    rig: RigOption = None,
    as_json: JsonFlag = False,
    json_out: Annotated[
        Path | None, typer.Option("--json-out", help="Also write the full JSON result here.")
    ] = None,
    pairings_out: Annotated[
        Path | None,
        typer.Option(
            "--pairings",
            help="Write each frame's corrected timing (FramePairing) to a log: .mcap, .bag or a .db3 bag dir.",
        ),
    ] = None,
    html_out: Annotated[
        Path | None, typer.Option("--html", help="Write a self-contained HTML report here.")
    ] = None,
    csv_out: Annotated[
        Path | None, typer.Option("--csv", help="Write the per-frame table as CSV here.")
    ] = None,
    gate: Annotated[
        bool, typer.Option("--gate", help="Exit 10 when a camera crosses a threshold (CI gate).")
    ] = False,
    jobs: Annotated[
        int | None,
        typer.Option("--jobs", "-j", help="Worker processes for MCAP chunks (default: cores)."),
    ] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing --pairings log.")] = False,
    check_crc: Annotated[
        bool, typer.Option(help="Verify every MCAP chunk's CRC (a quarter to a third slower).")
    ] = False,
) -> None:
    """Audit LiDAR-camera sync: Eq. 1-6 per camera, recommended delay, threshold verdict."""
    from syncaudit.audit import audit_log
    from syncaudit.errors import GateFailedError
    from syncaudit.report.console import render_audit
    from syncaudit.rig import load_rig
    from syncaudit.writers.atomic import write_atomic, write_text_atomic

    def job() -> None:
        result = audit_log(log, load_rig(rig) if rig else None, jobs=jobs, check_crc=check_crc)
        data = result.to_dict()
        if json_out:
            write_text_atomic(json_out, json.dumps(data, indent=2, allow_nan=False) + "\n")
        if pairings_out:
            from syncaudit.writers.pairings import write_pairings

            if pairings_out.exists() and not overwrite:
                raise OutputError(f"{pairings_out} exists (pass --overwrite to replace it)")
            write_pairings(result, pairings_out, overwrite=overwrite)
        if html_out:
            from syncaudit.report.html import render_audit_html

            write_text_atomic(html_out, render_audit_html(result))
        if csv_out:
            frames = result.frames()
            write_atomic(csv_out, lambda handle: frames.to_csv(handle, index=False))
        if as_json:
            _print_json(data)
        else:
            render_audit(result, stdout)
        if gate and not result.passed:
            raise GateFailedError(f"{log}: sync audit failed ({data['verdict']})")

    _run(job)


LIDAR_MODELS: tuple[str, ...] = get_args(LidarModel)


@app.command()
def simulate(
    out: Annotated[
        Path, typer.Argument(help="Output log (.mcap file, .db3 bag directory or .bag).")
    ],
    lidar: Annotated[str, typer.Option(help=f"LiDAR model: {', '.join(LIDAR_MODELS)}.")] = "VLP-16",
    duration_s: Annotated[float, typer.Option("--duration", help="Seconds of log.")] = 10.0,
    seed: Annotated[int, typer.Option(help="Random seed (the log is a pure function of it).")] = 0,
    fmt: Annotated[
        str | None,
        typer.Option("--format", help="mcap, mcap-ros1, db3 or bag (default: from OUT)."),
    ] = None,
    delay_error_us: Annotated[
        float, typer.Option(help="Applied delay minus the ideal one, every camera.")
    ] = 0.0,
    clock_offset_s: Annotated[float, typer.Option(help="LiDAR clock minus host clock.")] = 0.0,
    drop_fraction: Annotated[float, typer.Option(help="Fraction of packets dropped.")] = 0.001,
    controller: Annotated[
        bool, typer.Option(help="Run the self-adaptive controller live while recording.")
    ] = False,
    tunnel: Annotated[
        bool, typer.Option(help="Drive through a tunnel (exposure 2 -> 12 -> 2 ms).")
    ] = True,
    compressed: Annotated[bool, typer.Option(help="CompressedImage instead of Image.")] = False,
    overwrite: Annotated[bool, typer.Option(help="Replace OUT if it exists.")] = False,
    calib: Annotated[
        bool,
        typer.Option(
            "--calib",
            help="Write a turntable calibration session of non-overlapping LiDARs instead.",
        ),
    ] = False,
    beams: Annotated[int, typer.Option(help="--calib: beams per LiDAR (32 or 128-class).")] = 32,
    stops: Annotated[int, typer.Option(help="--calib: turntable stops.")] = 12,
    rotation_error_deg: Annotated[
        float, typer.Option(help="--calib: recorded rear extrinsic's rotation error.")
    ] = 0.05,
    translation_error_cm: Annotated[
        float, typer.Option(help="--calib: recorded rear extrinsic's translation error.")
    ] = 0.3,
    degenerate: Annotated[
        bool, typer.Option(help="--calib: a scene of ground and one wall only.")
    ] = False,
) -> None:
    """Write a log with known ground truth (OUT.truth.json) and its rig file (OUT.rig.yaml).

    With --calib: a turntable session of two non-overlapping LiDARs (PointCloud2 per stop,
    /tf_static with a perturbed recorded extrinsic) and its truth (OUT.truth.json).
    """
    if calib:
        _simulate_calib(
            out, seed, beams, stops, rotation_error_deg, translation_error_cm, degenerate, overwrite
        )
        return
    import yaml

    from syncaudit.analysis.controller import ControllerConfig
    from syncaudit.errors import ConfigError, validation_summary
    from syncaudit.simulate.rig_file import rig_from_truth
    from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log
    from syncaudit.writers.atomic import write_text_atomic
    from syncaudit.writers.log_writer import infer_format

    def job() -> None:
        from pydantic import ValidationError

        if lidar not in LIDAR_MODELS:
            raise ConfigError(f"--lidar must be one of {', '.join(LIDAR_MODELS)}, got {lidar!r}")
        try:
            base = SyncSimConfig()
            light = (
                base.light
                if tunnel
                else base.light.model_copy(
                    update={"dark_exposure_us": base.light.bright_exposure_us}
                )
            )
            config = SyncSimConfig.model_validate(
                {
                    "seed": seed,
                    "duration_s": duration_s,
                    "log_format": fmt or infer_format(out),
                    "overwrite": overwrite,
                    "lidar_model": lidar,
                    "clock_offset_ns": round(clock_offset_s * 1e9),
                    "packet_drop_fraction": drop_fraction,
                    "light": light,
                    "cameras": [
                        c.model_copy(update={"delay_error_us": delay_error_us})
                        for c in base.cameras
                    ],
                    "image_kind": "compressed" if compressed else "raw",
                    "controller": ControllerConfig() if controller else None,
                }
            )
        except ValidationError as exc:
            raise ConfigError(validation_summary(exc)) from exc
        if out.exists() and not overwrite:
            raise ConfigError(f"{out} exists (pass --overwrite to replace it)")
        truth = simulate_sync_log(out, config)
        rig = rig_from_truth(truth).model_dump(mode="json", exclude_defaults=True)
        rig_path = out.with_name(out.name + ".rig.yaml")
        write_text_atomic(rig_path, yaml.safe_dump(rig, sort_keys=False))
        lidar_truth = truth["lidar"]
        out_lines = [
            f"wrote {out} ({lidar_truth['model']}, {lidar_truth['revolutions']} revolutions, "
            f"{len(truth['cameras'])} cameras)",
            f"truth {out.name}.truth.json, rig {rig_path.name}",
        ]
        for line in out_lines:
            stdout.print(line, highlight=False)

    _run(job)


def _simulate_calib(
    out: Path,
    seed: int,
    beams: int,
    stops: int,
    rotation_error_deg: float,
    translation_error_cm: float,
    degenerate: bool,
    overwrite: bool,
) -> None:
    from syncaudit.calib.config import CalibSceneConfig, SceneConfig, rig_preset
    from syncaudit.errors import ConfigError
    from syncaudit.simulate.calib_session import simulate_calib_session

    def job() -> None:
        if out.exists() and not overwrite:
            raise ConfigError(f"{out} exists (pass --overwrite to replace it)")
        # The calibration's config models raise one-line ConfigErrors themselves.
        config = CalibSceneConfig(
            seed=seed,
            n_stops=stops,
            scene=SceneConfig(kind="ground_and_wall" if degenerate else "yard"),
            lidars=rig_preset(
                beams,
                rear_rotation_error_deg=rotation_error_deg,
                rear_translation_error_cm=translation_error_cm,
            ),
        )
        simulate_calib_session(out, config, fmt=None, overwrite=overwrite)
        stdout.print(
            f"wrote {out} ({stops} stops, {beams}-beam LiDARs), truth {out.name}.truth.json",
            highlight=False,
        )

    _run(job)


@app.command()
def calib(
    log: Annotated[Path, typer.Argument(help="Log with PointCloud2 of two or more LiDARs.")],
    config_file: Annotated[
        Path | None, typer.Option("--config", help="Calibration config (YAML/TOML/JSON).")
    ] = None,
    extrinsics: Annotated[
        Path | None,
        typer.Option(help="Recorded extrinsics file to validate (default: /tf_static in the log)."),
    ] = None,
    topics: Annotated[
        str | None, typer.Option(help="Comma-separated PointCloud2 topics (default: all).")
    ] = None,
    as_json: JsonFlag = False,
    json_out: Annotated[
        Path | None, typer.Option("--json-out", help="Also write the JSON result here.")
    ] = None,
    html_out: Annotated[
        Path | None, typer.Option("--html", help="Write an HTML report here.")
    ] = None,
    gate: Annotated[
        bool,
        typer.Option("--gate", help="Exit 10 when validation fails or calibration is impossible."),
    ] = False,
) -> None:
    """Calibrate non-overlapping LiDARs (ICP, pose graph, map-to-map ICP) and validate the
    recorded extrinsics (method B)."""
    from syncaudit.errors import ConfigError, GateFailedError
    from syncaudit.writers.atomic import write_text_atomic

    def job() -> None:
        try:
            from syncaudit.calib import (
                CalibConfig,
                calibrate_log,
                html_section,
                load_config,
                render_calibration,
            )
        except ImportError as exc:  # pragma: no cover - depends on the install
            raise ConfigError(
                f"the calibration needs the optional extra: pip install 'syncaudit[calib]' ({exc})"
            ) from exc
        config: CalibConfig = (
            load_config(config_file, CalibConfig) if config_file else CalibConfig()
        )
        updates: dict[str, object] = {}
        if extrinsics is not None:
            updates["extrinsics_file"] = extrinsics
        if topics:
            updates["lidar_topics"] = [t.strip() for t in topics.split(",") if t.strip()]
        if updates:
            config = CalibConfig.model_validate({**config.model_dump(), **updates})
        result = calibrate_log(log, config)
        data = result.to_json_dict()
        if json_out:
            write_text_atomic(json_out, json.dumps(data, indent=2, allow_nan=False) + "\n")
        if html_out:
            page = (
                "<!doctype html><html lang=en><head><meta charset=utf-8>"
                f"<title>syncaudit calib</title></head><body>{html_section(result)}</body></html>\n"
            )
            write_text_atomic(html_out, page)
        if as_json:
            _print_json(data)
        else:
            render_calibration(result, stdout)
        if gate and not result.passed:
            why = result.reason or "recorded extrinsics outside the limits"
            raise GateFailedError(f"{log}: calibration check failed: {why}")

    _run(job)


register_fleet(app)  # syncaudit gate, syncaudit fleet report (src/syncaudit/fleet/cli.py)


def main() -> None:
    """Console-script entry point.

    Exits without the interpreter's teardown (~60 ms with numpy and pandas loaded): by
    then every output file is written and closed, and the streams are flushed here.
    """
    try:
        app()
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        if exc.code is not None and not isinstance(exc.code, int):
            print(exc.code, file=sys.stderr)
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except (BrokenPipeError, OSError):  # a reader that went away (e.g. `| head`)
        code = code or 1
    os._exit(code)


if __name__ == "__main__":
    main()
