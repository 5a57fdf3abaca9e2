"""`syncaudit simulate sync|calib`: logs with known ground truth."""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, get_args

import typer

from syncaudit.cli.common import OverwriteFlag, SyncauditGroup, app, emit, output_set, run
from syncaudit.errors import ConfigError, UsageError
from syncaudit.simulate import LidarModel

if TYPE_CHECKING:
    from syncaudit.writers.log_writer import LogFormat

simulate_app = typer.Typer(
    cls=SyncauditGroup,
    help="Write a log with known ground truth: `sync` (LiDAR + cameras) or `calib` (LiDARs).",
    no_args_is_help=True,
    rich_markup_mode=None,
)
app.add_typer(simulate_app, name="simulate")

LIDAR_MODELS: tuple[str, ...] = get_args(LidarModel)
FORMATS = ("mcap", "mcap-ros1", "db3", "bag")

OutArgument = Annotated[
    Path,
    typer.Argument(
        help="Output log: .mcap, .bag, or a ROS 2 bag folder (no suffix, or NAME.db3 -> NAME)."
    ),
]
SeedOption = Annotated[
    int, typer.Option("--seed", help="Random seed (the log is a pure function of it).")
]
FormatOption = Annotated[
    str | None,
    typer.Option(
        "--format",
        help=f"Log format: {', '.join(FORMATS)} (default: from OUT's suffix).",
    ),
]


_OPTION_OF_FIELD: dict[str, str] = {
    "duration_s": "--duration",
    "packet_drop_fraction": "--drop-fraction",
    "clock_offset_ns": "--clock-offset-s",
    "delay_error_us": "--delay-error-us",
    "lidar_model": "--lidar",
    "trigger_packet_offset": "--trigger-packet-offset",
    "trigger_packet": "--trigger-packet",
    "ros1_header_seq": "--ros1-seq",
    "log_format": "--format",
    "n_stops": "--stops",
    "scans_per_stop": "--scans-per-stop",
    "turning_scans": "--turning-scans",
    "beams": "--beams",
    "recorded_rotation_error_deg": "--rotation-error-deg",
    "recorded_translation_error_cm": "--translation-error-cm",
}
"""Simulator config fields and the options that set them, for messages in the user's words."""


def _usage(exc: ConfigError) -> UsageError:
    """A setting the simulator's config refused, worded with the options the user typed."""
    detail = str(exc)
    if detail.startswith("invalid "):
        detail = detail.split(": ", 1)[-1]
    detail = detail.removeprefix("(top level): ")
    for field, option in _OPTION_OF_FIELD.items():
        detail = re.sub(rf"(?<![\w-]){field}\b", option, detail)
    return UsageError(detail)


@simulate_app.command("sync")
def simulate_sync(
    out: OutArgument,
    lidar: Annotated[
        str,
        typer.Option(
            "--lidar",
            help=f"LiDAR model: {', '.join(LIDAR_MODELS)} (case-insensitive; XT32 = PandarXT32).",
        ),
    ] = "VLP-16",
    duration_s: Annotated[
        float, typer.Option("--duration", min=0.001, max=3600.0, help="Seconds of log.")
    ] = 10.0,
    seed: SeedOption = 0,
    fmt: FormatOption = None,
    delay_error_us: Annotated[
        float,
        typer.Option(
            "--delay-error-us",
            min=-1e6,
            max=1e6,
            help="Applied trigger delay minus the ideal one, every camera (us).",
        ),
    ] = 0.0,
    clock_offset_s: Annotated[
        float,
        typer.Option(
            "--clock-offset-s", min=-1e9, max=1e9, help="LiDAR clock minus host clock (s)."
        ),
    ] = 0.0,
    drop_fraction: Annotated[
        float,
        typer.Option("--drop-fraction", min=0.0, max=0.5, help="Fraction of packets dropped."),
    ] = 0.001,
    controller: Annotated[
        bool,
        typer.Option("--controller", help="Run the self-adaptive delay controller live."),
    ] = False,
    tunnel: Annotated[
        bool,
        typer.Option(
            "--tunnel/--no-tunnel", help="Drive through a tunnel (exposure 2 -> 12 -> 2 ms)."
        ),
    ] = True,
    compressed: Annotated[
        bool, typer.Option("--compressed", help="CompressedImage instead of Image.")
    ] = False,
    trigger_packet: Annotated[
        str,
        typer.Option(
            "--trigger-packet",
            help="Packet the triggers are issued from: 'containing' the zero crossing, or "
            "'first_after' it (a driver that cuts revolutions by packet).",
        ),
    ] = "containing",
    trigger_packet_offset: Annotated[
        int,
        typer.Option(
            "--trigger-packet-offset",
            min=-32,
            max=32,
            help="Move the trigger packet by this many delivered packets (+ later, - earlier).",
        ),
    ] = 0,
    ros1_seq: Annotated[
        bool,
        typer.Option(
            "--ros1-seq/--no-ros1-seq",
            help="ROS 1 formats: number header seq per frame, or write 0 as some drivers do.",
        ),
    ] = True,
    overwrite: OverwriteFlag = False,
) -> None:
    """Write a LiDAR + three cameras log, its truth (OUT.truth.json) and rig (OUT.rig.yaml)."""

    def job() -> None:
        from syncaudit.simulate.sync_log import lidar_model, sync_sim_config
        from syncaudit.writers.log_writer import infer_format, log_target

        try:
            model = lidar_model(lidar)
        except ConfigError as exc:
            raise UsageError(f"--lidar: {exc}") from None
        log_format = _format(out, fmt)
        target = log_target(out, log_format)
        try:
            config = sync_sim_config(
                lidar=model,
                tunnel=tunnel,
                delay_error_us=delay_error_us,
                clock_offset_s=clock_offset_s,
                compressed=compressed,
                controller=controller,
                seed=seed,
                duration_s=duration_s,
                log_format=infer_format(target, log_format),
                overwrite=overwrite,
                packet_drop_fraction=drop_fraction,
                trigger_packet=trigger_packet,
                trigger_packet_offset=trigger_packet_offset,
                ros1_header_seq=ros1_seq,
            )
        except ConfigError as exc:
            raise _usage(exc) from None
        import yaml

        from syncaudit.simulate.rig_file import rig_from_truth, rig_path
        from syncaudit.simulate.sync_log import simulate_sync_log, truth_path

        rig_file = rig_path(target)
        with output_set(overwrite=overwrite, targets=(rig_file,)) as outputs:
            truth = simulate_sync_log(target, config, outputs=outputs)
            rig = rig_from_truth(truth).model_dump(mode="json", exclude_defaults=True)
            outputs.write_text(rig_file, yaml.safe_dump(rig, sort_keys=False))
        lidar_truth = truth["lidar"]
        lines = [
            f"wrote {target} ({lidar_truth['model']}, {lidar_truth['revolutions']} revolutions, "
            f"{len(truth['cameras'])} cameras)",
            f"truth {truth_path(target)}",
            f"rig {rig_file}",
        ]
        emit(lambda: print("\n".join(lines)))

    run(job)


def _format(out: Path, fmt: str | None) -> LogFormat:
    """The log format for OUT: `--format` if given (it must fit OUT's suffix), else the suffix."""
    from syncaudit.writers.log_writer import infer_format

    if fmt is not None and fmt.lower() not in FORMATS:
        raise UsageError(f"--format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    try:
        return infer_format(out, fmt.lower() if fmt else None)  # type: ignore[arg-type]
    except ConfigError as exc:
        raise UsageError(f"--format: {exc}" if fmt else str(exc)) from None


@simulate_app.command("calib")
def simulate_calib(
    out: OutArgument,
    beams: Annotated[
        int,
        typer.Option(
            "--beams",
            min=2,
            max=512,
            help="Beams per LiDAR: up to 32 a VLP-32C-like pattern, more an OS1-128-like one.",
        ),
    ] = 32,
    stops: Annotated[
        int, typer.Option("--stops", min=2, max=720, help="Turntable stops (2 or more).")
    ] = 12,
    rotation_error_deg: Annotated[
        float,
        typer.Option(
            "--rotation-error-deg",
            min=0.0,
            max=45.0,
            help="Rotation error of the rear LiDAR's recorded extrinsic (deg).",
        ),
    ] = 0.05,
    translation_error_cm: Annotated[
        float,
        typer.Option(
            "--translation-error-cm",
            min=0.0,
            max=100.0,
            help="Translation error of the rear LiDAR's recorded extrinsic (cm).",
        ),
    ] = 0.3,
    degenerate: Annotated[
        bool,
        typer.Option(
            "--degenerate", help="A scene of ground and one wall only (not calibratable)."
        ),
    ] = False,
    scans_per_stop: Annotated[
        int,
        typer.Option(
            "--scans-per-stop",
            min=1,
            max=50,
            help="Scans each LiDAR records per stop (2 or more lets calib find the stops).",
        ),
    ] = 1,
    turning_scans: Annotated[
        int,
        typer.Option(
            "--turning-scans",
            min=0,
            max=50,
            help="Scans recorded while turning between stops (needs --scans-per-stop >= 2).",
        ),
    ] = 0,
    seed: SeedOption = 0,
    fmt: FormatOption = None,
    overwrite: OverwriteFlag = False,
) -> None:
    """Write a turntable session of two non-overlapping LiDARs and its truth (OUT.truth.json)."""

    def job() -> None:
        from syncaudit.calib.config import CalibSceneConfig, SceneConfig, rig_preset
        from syncaudit.simulate.calib_session import simulate_calib_session, truth_path
        from syncaudit.writers.log_writer import log_target

        log_format = _format(out, fmt)
        target = log_target(out, log_format)
        try:
            config = CalibSceneConfig(
                seed=seed,
                n_stops=stops,
                scans_per_stop=scans_per_stop,
                turning_scans=turning_scans,
                scene=SceneConfig(kind="ground_and_wall" if degenerate else "yard"),
                lidars=rig_preset(
                    beams,
                    rear_rotation_error_deg=rotation_error_deg,
                    rear_translation_error_cm=translation_error_cm,
                ),
            )
        except ConfigError as exc:
            raise _usage(exc) from None
        with output_set(overwrite=overwrite) as outputs:
            simulate_calib_session(
                target,
                config,
                fmt=log_format,
                overwrite=overwrite,
                outputs=outputs,
            )
        line = f"wrote {target} ({stops} stops, {beams}-beam LiDARs), truth {truth_path(target)}"
        emit(lambda: print(line))

    run(job)
