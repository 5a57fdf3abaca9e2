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
    "shared_topics": "--shared-topics",
    "trigger_message": "--trigger-message",
    "exposure_messages": "--exposure-messages",
    "header_frame_ids": "--frame-ids",
    "camera_field": "--camera-field",
    "stamp_semantics": "--stamp",
    "log_format": "--format",
    "n_stops": "--stops",
    "scans_per_stop": "--scans-per-stop",
    "turning_scans": "--turning-scans",
    "beams": "--beams",
    "recorded_rotation_error_deg": "--rotation-error-deg",
    "recorded_translation_error_cm": "--translation-error-cm",
    "range_noise_m": "--range-noise-m",
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
    stamp: Annotated[
        str,
        typer.Option(
            "--stamp",
            help="What every camera's image header stamp marks: exposure_start, "
            "exposure_middle, exposure_end or trigger (246).",
        ),
    ] = "exposure_start",
    exposure_messages: Annotated[
        str,
        typer.Option(
            "--exposure-messages",
            help="Comma-separated exposure metadata to write: camera_exposure (states its "
            "start), flir_meta (ImageMetaData: the start follows --stamp); '' for none.",
        ),
    ] = "camera_exposure,flir_meta",
    shared_topics: Annotated[
        str,
        typer.Option(
            "--shared-topics",
            help="Comma-separated kinds every camera publishes on one topic (image, "
            "exposure, meta, trigger), told apart by header.frame_id.",
        ),
    ] = "",
    trigger_message: Annotated[
        str,
        typer.Option(
            "--trigger-message",
            help="The trigger record: trigger_event (TriggerEvent, five checkpoints) or "
            "time_reference (sensor_msgs/TimeReference: 246 only, numbered by header seq).",
        ),
    ] = "trigger_event",
    frame_ids: Annotated[
        bool,
        typer.Option(
            "--frame-ids/--no-frame-ids",
            help="Write each camera's frame in header.frame_id, or leave it empty.",
        ),
    ] = True,
    camera_field: Annotated[
        bool,
        typer.Option(
            "--camera-field/--no-camera-field",
            help="Write the camera name in CameraExposure/TriggerEvent.camera, or leave it empty.",
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
                stamp=stamp,
                exposure_messages=_names(exposure_messages),
                shared_topics=_names(shared_topics),
                trigger_message=trigger_message,
                header_frame_ids=frame_ids,
                camera_field=camera_field,
            )
        except ConfigError as exc:
            raise _usage(exc) from None
        import yaml

        from syncaudit.simulate.rig_file import rig_from_truth, rig_path
        from syncaudit.simulate.sync_log import simulate_sync_log, truth_path
        from syncaudit.writers.provenance import COMMENT_MARK

        rig_file = rig_path(target)
        with output_set(overwrite=overwrite, targets=(rig_file,)) as outputs:
            truth = simulate_sync_log(target, config, outputs=outputs)
            rig = rig_from_truth(truth).model_dump(mode="json", exclude_defaults=True)
            outputs.write_text(rig_file, COMMENT_MARK + yaml.safe_dump(rig, sort_keys=False))
        lidar_truth = truth["lidar"]
        lines = [
            f"wrote {target} ({lidar_truth['model']}, {lidar_truth['revolutions']} revolutions, "
            f"{len(truth['cameras'])} cameras)",
            f"truth {truth_path(target)}",
            f"rig {rig_file}",
        ]
        emit(lambda: print("\n".join(lines)))

    run(job)


def _names(option: str) -> tuple[str, ...]:
    """A comma-separated option as a tuple of names ('' -> none)."""
    return tuple(name.strip() for name in option.split(",") if name.strip())


def _format(out: Path, fmt: str | None) -> LogFormat:
    """The log format for OUT: `--format` if given (it must fit OUT's suffix), else the suffix."""
    from syncaudit.writers.log_writer import infer_format

    if fmt is not None and fmt.lower() not in FORMATS:
        raise UsageError(f"--format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    try:
        return infer_format(out, fmt.lower() if fmt else None)  # type: ignore[arg-type]
    except ConfigError as exc:
        raise UsageError(f"--format: {exc}" if fmt else str(exc)) from None


MOUNTS = ("roof_front_rear", "roof_left_right", "bumper_front_rear", "diagonal")
MOTIONS = ("turntable", "drive")
ORGANIZED = ("none", "second", "both")
TF_CHAINS = ("direct", "sensor_kit")
ODOMETRY = ("none", "odometry", "tf", "both")
SCENES = ("yard", "ground_and_wall", "corridor")
BEAMS = (16, 32, 64, 128)


def _choice(option: str, value: str, allowed: tuple[str, ...]) -> str:
    """`value` if it is one of `allowed` (case-insensitive), else a usage error naming the option."""
    if value.lower() not in allowed:
        raise UsageError(f"{option} must be one of {'|'.join(allowed)}, got {value!r}")
    return value.lower()


@simulate_app.command("calib")
def simulate_calib(
    out: OutArgument,
    beams: Annotated[
        int,
        typer.Option(
            "--beams",
            help="Beams per LiDAR: 16 (VLP-16-like), 32 (VLP-32C-like), 64 or 128 (OS1-like).",
        ),
    ] = 32,
    stops: Annotated[
        int, typer.Option("--stops", min=2, max=720, help="Stops of the session (2 or more).")
    ] = 12,
    mount: Annotated[
        str, typer.Option("--mount", help=f"Where the two LiDARs sit: {'|'.join(MOUNTS)}.")
    ] = "roof_front_rear",
    motion: Annotated[
        str,
        typer.Option(
            "--motion",
            help="turntable (pure turns about a pivot) or drive (25-45 deg turns and 0.3-1.1 m "
            "moves between short stops, motion-distorted scans while moving).",
        ),
    ] = "turntable",
    organized: Annotated[
        str,
        typer.Option(
            "--organized",
            help="Which LiDARs publish organised beam x column clouds (zeros for no return): "
            f"{'|'.join(ORGANIZED)}.",
        ),
    ] = "none",
    tf_chain: Annotated[
        str,
        typer.Option(
            "--tf-chain",
            help="/tf_static as base_link -> lidar (direct) or base_link -> sensor_kit_base_link "
            "-> lidar (sensor_kit).",
        ),
    ] = "direct",
    odometry: Annotated[
        str,
        typer.Option(
            "--odometry",
            help="The vehicle's drifting odometry: none, odometry (nav_msgs/Odometry on /odom), "
            "tf (/tf odom -> base_link) or both.",
        ),
    ] = "none",
    scene: Annotated[
        str,
        typer.Option(
            "--scene",
            help="yard (walls, boxes, poles), ground_and_wall or corridor (both degenerate: "
            "not calibratable).",
        ),
    ] = "yard",
    range_noise_m: Annotated[
        float,
        typer.Option(
            "--range-noise-m", min=0.0, max=0.5, help="Range noise of every LiDAR (m, 1 sigma)."
        ),
    ] = 0.01,
    rotation_error_deg: Annotated[
        float,
        typer.Option(
            "--rotation-error-deg",
            min=0.0,
            max=45.0,
            help="Rotation error of the second LiDAR's recorded extrinsic (deg).",
        ),
    ] = 0.05,
    translation_error_cm: Annotated[
        float,
        typer.Option(
            "--translation-error-cm",
            min=0.0,
            max=100.0,
            help="Translation error of the second LiDAR's recorded extrinsic (cm).",
        ),
    ] = 0.3,
    degenerate: Annotated[
        bool,
        typer.Option("--degenerate", help="Alias of --scene ground_and_wall."),
    ] = False,
    scans_per_stop: Annotated[
        int | None,
        typer.Option(
            "--scans-per-stop",
            min=1,
            max=50,
            help="Turntable: scans each LiDAR records per stop (default 1; 2 or more lets "
            "calib find the stops). drive sessions stand 0.45-0.8 s per stop.",
        ),
    ] = None,
    turning_scans: Annotated[
        int | None,
        typer.Option(
            "--turning-scans",
            min=0,
            max=50,
            help="Turntable: scans recorded while turning between stops (needs "
            "--scans-per-stop >= 2). drive sessions record 10-18 per move.",
        ),
    ] = None,
    seed: SeedOption = 0,
    fmt: FormatOption = None,
    overwrite: OverwriteFlag = False,
) -> None:
    """Write a calibration session of two non-overlapping LiDARs and its truth (OUT.truth.json)."""

    def job() -> None:
        from syncaudit.calib.settings import calib_scene_config
        from syncaudit.simulate.calib_session import simulate_calib_session, truth_path
        from syncaudit.writers.log_writer import log_target

        if beams not in BEAMS:
            raise UsageError(f"--beams must be one of {'|'.join(map(str, BEAMS))}, got {beams}")
        chosen = {
            "mount": _choice("--mount", mount, MOUNTS),
            "motion": _choice("--motion", motion, MOTIONS),
            "organized": _choice("--organized", organized, ORGANIZED),
            "tf_chain": _choice("--tf-chain", tf_chain, TF_CHAINS),
            "odometry": _choice("--odometry", odometry, ODOMETRY),
            "scene": _choice("--scene", scene, SCENES),
        }
        if degenerate:
            if chosen["scene"] not in ("yard", "ground_and_wall"):
                raise UsageError(f"--degenerate conflicts with --scene {chosen['scene']}")
            chosen["scene"] = "ground_and_wall"
        turntable_only = {"--scans-per-stop": scans_per_stop, "--turning-scans": turning_scans}
        given = [name for name, value in turntable_only.items() if value is not None]
        if chosen["motion"] == "drive" and given:
            raise UsageError(f"{' and '.join(given)} only apply to --motion turntable")
        log_format = _format(out, fmt)
        target = log_target(out, log_format)
        try:
            config = calib_scene_config(
                beams=beams,
                n_stops=stops,
                seed=seed,
                range_noise_m=range_noise_m,
                rear_rotation_error_deg=rotation_error_deg,
                rear_translation_error_cm=translation_error_cm,
                **chosen,  # type: ignore[arg-type]
            )
            if chosen["motion"] == "turntable":
                config = type(config).model_validate(
                    {
                        **config.model_dump(),
                        "scans_per_stop": 1 if scans_per_stop is None else scans_per_stop,
                        "turning_scans": 0 if turning_scans is None else turning_scans,
                    }
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
        line = (
            f"wrote {target} ({chosen['motion']}, {stops} stops, {beams}-beam LiDARs "
            f"{chosen['mount']}, {chosen['scene']}), truth {truth_path(target)}"
        )
        emit(lambda: print(line))

    run(job)
