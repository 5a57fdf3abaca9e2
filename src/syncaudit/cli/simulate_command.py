"""`syncaudit simulate sync|calib`: logs with known ground truth."""

from __future__ import annotations

import re
import typing
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, get_args

import typer

from syncaudit.cli.common import (
    OverwriteFlag,
    SyncauditGroup,
    app,
    emit,
    option_error,
    output_set,
    run,
)
from syncaudit.errors import ConfigError, UsageError
from syncaudit.simulate import LidarModel, SceneKind

if TYPE_CHECKING:
    from syncaudit.analysis.controller import ControllerConfig
    from syncaudit.simulate.calib_config import CalibSceneConfig
    from syncaudit.simulate.delays import CompensatedDelays, LiveDelays
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
    int | None, typer.Option("--seed", help="Random seed (the log is a pure function of it).")
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
    """A setting the simulator's config refused, worded with the options the user typed:
    the key it names, then any field the model's own sentence names."""
    detail = str(option_error(exc, _OPTION_OF_FIELD))
    for field, option in _OPTION_OF_FIELD.items():
        detail = re.sub(rf"(?<![\w-]){field}\b", option, detail)
    return UsageError(detail)


ConfigOption = Annotated[
    Path | None,
    typer.Option(
        "--config",
        help="Simulator settings from a YAML, TOML or JSON file (the simulator config's "
        "fields); the options given override it, those left out keep its values, then the "
        "config's defaults.",
    ),
]


@simulate_app.command("sync")
def simulate_sync(
    out: OutArgument,
    config_file: ConfigOption = None,
    lidar: Annotated[
        str | None,
        typer.Option(
            "--lidar",
            help=f"LiDAR model: {', '.join(LIDAR_MODELS)} (case-insensitive; XT32 = PandarXT32, ouster = OS-1-64).",
        ),
    ] = None,
    duration_s: Annotated[
        float | None,
        typer.Option("--duration", min=0.001, max=14_400.0, help="Seconds of log (up to 4 h)."),
    ] = None,
    seed: SeedOption = None,
    fmt: FormatOption = None,
    delay_error_us: Annotated[
        float | None,
        typer.Option(
            "--delay-error-us",
            min=-1e6,
            max=1e6,
            help="Applied trigger delay minus the ideal one, every camera (us).",
        ),
    ] = None,
    clock_offset_s: Annotated[
        float | None,
        typer.Option(
            "--clock-offset-s", min=-1e9, max=1e9, help="LiDAR clock minus host clock (s)."
        ),
    ] = None,
    drop_fraction: Annotated[
        float | None,
        typer.Option("--drop-fraction", min=0.0, max=0.5, help="Fraction of packets dropped."),
    ] = None,
    controller: Annotated[
        bool,
        typer.Option(
            "--controller",
            help="Run the self-adaptive delay controller live (settings: the config file's "
            "`controller` mapping, else the controller's defaults).",
        ),
    ] = False,
    delay_source: Annotated[
        str | None,
        typer.Option(
            "--delays",
            help="Where each frame's trigger delay comes from: constant (default), controller "
            "(as --controller) or compensated (each frame's own exposure compensated exactly, "
            "as a rig with exposure feed-forward).",
        ),
    ] = None,
    tunnel: Annotated[
        bool | None,
        typer.Option(
            "--tunnel/--no-tunnel", help="Drive through a tunnel (exposure 2 -> 12 -> 2 ms)."
        ),
    ] = None,
    compressed: Annotated[
        bool, typer.Option("--compressed", help="CompressedImage instead of Image.")
    ] = False,
    trigger_packet: Annotated[
        str | None,
        typer.Option(
            "--trigger-packet",
            help="Packet the triggers are issued from: 'containing' the zero crossing, or "
            "'first_after' it (a driver that cuts revolutions by packet).",
        ),
    ] = None,
    trigger_packet_offset: Annotated[
        int | None,
        typer.Option(
            "--trigger-packet-offset",
            min=-32,
            max=32,
            help="Move the trigger packet by this many delivered packets (+ later, - earlier).",
        ),
    ] = None,
    ros1_seq: Annotated[
        bool | None,
        typer.Option(
            "--ros1-seq/--no-ros1-seq",
            help="ROS 1 formats: number header seq per frame, or write 0 as some drivers do.",
        ),
    ] = None,
    stamp: Annotated[
        str | None,
        typer.Option(
            "--stamp",
            help="What every camera's image header stamp marks: exposure_start, "
            "exposure_middle, exposure_end or trigger (246).",
        ),
    ] = None,
    exposure_messages: Annotated[
        str | None,
        typer.Option(
            "--exposure-messages",
            help="Comma-separated exposure metadata to write: camera_exposure (states its "
            "start), flir_meta (ImageMetaData: the start follows --stamp); '' for none.",
        ),
    ] = None,
    shared_topics: Annotated[
        str | None,
        typer.Option(
            "--shared-topics",
            help="Comma-separated kinds every camera publishes on one topic (image, "
            "exposure, meta, trigger), told apart by header.frame_id.",
        ),
    ] = None,
    trigger_message: Annotated[
        str | None,
        typer.Option(
            "--trigger-message",
            help="The trigger record: trigger_event (TriggerEvent, five checkpoints) or "
            "time_reference (sensor_msgs/TimeReference: 246 only, numbered by header seq).",
        ),
    ] = None,
    frame_ids: Annotated[
        bool | None,
        typer.Option(
            "--frame-ids/--no-frame-ids",
            help="Write each camera's frame in header.frame_id, or leave it empty.",
        ),
    ] = None,
    camera_field: Annotated[
        bool | None,
        typer.Option(
            "--camera-field/--no-camera-field",
            help="Write the camera name in CameraExposure/TriggerEvent.camera, or leave it empty.",
        ),
    ] = None,
    overwrite: OverwriteFlag = False,
) -> None:
    """Write a LiDAR + three cameras log, its truth (OUT.truth.json) and rig (OUT.rig.yaml)."""

    def job() -> None:
        from syncaudit.simulate.sync_log import lidar_model, sync_sim_config
        from syncaudit.writers.log_writer import infer_format, log_target

        base, controller_file = _sync_file(config_file) if config_file else ({}, None)
        try:
            model = None if lidar is None else lidar_model(lidar)
        except ConfigError as exc:
            raise UsageError(f"--lidar: {exc}") from None
        log_format = _format(out, fmt)
        target = log_target(out, log_format)
        fields = {
            "seed": seed,
            "duration_s": duration_s,
            "packet_drop_fraction": drop_fraction,
            "trigger_packet": trigger_packet,
            "trigger_packet_offset": trigger_packet_offset,
            "ros1_header_seq": ros1_seq,
            "exposure_messages": None if exposure_messages is None else _names(exposure_messages),
            "shared_topics": None if shared_topics is None else _names(shared_topics),
            "trigger_message": trigger_message,
            "header_frame_ids": frame_ids,
            "camera_field": camera_field,
        }
        try:
            config = sync_sim_config(
                base,
                lidar=model,
                tunnel=tunnel,
                delay_error_us=delay_error_us,
                clock_offset_s=clock_offset_s,
                compressed=True if compressed else None,
                stamp=stamp,
                log_format=infer_format(target, log_format),
                overwrite=overwrite,
                **{name: value for name, value in fields.items() if value is not None},
            )
        except ConfigError as exc:
            raise _usage(exc) from None
        import yaml

        from syncaudit.simulate.rig_file import rig_from_truth, rig_path
        from syncaudit.simulate.sync_log import simulate_sync_log, truth_path
        from syncaudit.writers.provenance import COMMENT_MARK

        delays = _delay_source(delay_source, controller, controller_file)
        rig_file = rig_path(target)
        with output_set(overwrite=overwrite, targets=(rig_file,)) as outputs:
            truth = simulate_sync_log(target, config, outputs=outputs, delays=delays)
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


DELAY_SOURCES = ("constant", "controller", "compensated")


def _delay_source(
    name: str | None, controller: bool, controller_file: ControllerConfig | None
) -> LiveDelays | CompensatedDelays | None:
    """The simulator's delay source for `--delays` (and `--controller`, the config file's
    `controller`): None for constant delays. Usage error for an unknown name or a clash."""
    from syncaudit.cli.simulate_controller import ControllerDelays
    from syncaudit.simulate.delays import CompensatedDelays

    wants_controller = controller or controller_file is not None
    if name is not None and name not in DELAY_SOURCES:
        raise UsageError(f"--delays: {name!r} is not one of {', '.join(DELAY_SOURCES)}")
    if name in ("constant", "compensated") and wants_controller:
        raise UsageError(
            f"--delays {name} and the controller (--controller or the config file's "
            "`controller`): give one"
        )
    if name == "compensated":
        return CompensatedDelays()
    if name == "controller" or wants_controller:
        return ControllerDelays(controller_file)
    return None


def _sync_file(path: Path) -> tuple[dict[str, Any], ControllerConfig | None]:
    """A sync simulator config file: its SyncSimConfig fields (checked here, so a bad value
    names the file), and its `controller` (true or a mapping of controller settings:
    the controller runs; false, null or absent: constant delays unless --controller).

    Raises:
        ConfigError: `FILE: key: message` for the first bad key.
    """
    from pydantic import ValidationError

    from syncaudit.analysis.controller import ControllerConfig
    from syncaudit.config import load_mapping, validate_mapping
    from syncaudit.simulate.sync_log import SyncSimConfig

    what = "simulator config"
    raw = load_mapping(path, what=what)
    controller = raw.pop("controller", None)
    for fixed in ("log_format", "overwrite"):
        if fixed in raw:
            raise ConfigError(f"{path}: {fixed}: set by OUT, --format and --overwrite")
    validate_mapping(path, raw, SyncSimConfig, what=what)
    if controller is None or controller is False:
        return raw, None
    try:
        if controller is True:
            return raw, ControllerConfig()
        return raw, ControllerConfig.model_validate(controller)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(part) for part in ("controller", *first["loc"]))
        raise ConfigError(f"{path}: {where}: {first['msg']}") from None


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
SCENES: tuple[str, ...] = typing.get_args(SceneKind)
BEAMS = (16, 32, 64, 128)


def _choice(option: str, value: str, allowed: tuple[str, ...]) -> str:
    """`value` if it is one of `allowed` (case-insensitive), else a usage error naming the option."""
    if value.lower() not in allowed:
        raise UsageError(f"{option} must be one of {'|'.join(allowed)}, got {value!r}")
    return value.lower()


@simulate_app.command("calib")
def simulate_calib(
    out: OutArgument,
    config_file: ConfigOption = None,
    beams: Annotated[
        int | None,
        typer.Option(
            "--beams",
            help="Beams per LiDAR: 16 (VLP-16-like), 32 (VLP-32C-like), 64 or 128 (OS1-like).",
        ),
    ] = None,
    stops: Annotated[
        int | None,
        typer.Option("--stops", min=2, max=720, help="Stops of the session (2 or more)."),
    ] = None,
    mount: Annotated[
        str | None, typer.Option("--mount", help=f"Where the two LiDARs sit: {'|'.join(MOUNTS)}.")
    ] = None,
    motion: Annotated[
        str | None,
        typer.Option(
            "--motion",
            help="turntable (pure turns about a pivot) or drive (25-45 deg turns and 0.3-1.1 m "
            "moves between short stops, motion-distorted scans while moving).",
        ),
    ] = None,
    organized: Annotated[
        str | None,
        typer.Option(
            "--organized",
            help="Which LiDARs publish organised beam x column clouds (zeros for no return): "
            f"{'|'.join(ORGANIZED)}.",
        ),
    ] = None,
    tf_chain: Annotated[
        str | None,
        typer.Option(
            "--tf-chain",
            help="/tf_static as base_link -> lidar (direct) or base_link -> sensor_kit_base_link "
            "-> lidar (sensor_kit).",
        ),
    ] = None,
    odometry: Annotated[
        str | None,
        typer.Option(
            "--odometry",
            help="The vehicle's drifting odometry: none, odometry (nav_msgs/Odometry on /odom), "
            "tf (/tf odom -> base_link) or both.",
        ),
    ] = None,
    scene: Annotated[
        str | None,
        typer.Option(
            "--scene",
            help="yard (walls, boxes, poles), ground_and_wall or corridor (both degenerate: "
            "not calibratable), parking_lot (rows of parked cars, lamp posts, one building), "
            "parking_lot_open (cars on one side of the aisle only) or parking_lot_facing (a "
            "one-sided lot along the start heading: the rear LiDAR sees the cars at the first "
            "stops only).",
        ),
    ] = None,
    range_noise_m: Annotated[
        float | None,
        typer.Option(
            "--range-noise-m", min=0.0, max=0.5, help="Range noise of every LiDAR (m, 1 sigma)."
        ),
    ] = None,
    rotation_error_deg: Annotated[
        float | None,
        typer.Option(
            "--rotation-error-deg",
            min=0.0,
            max=45.0,
            help="Rotation error of the second LiDAR's recorded extrinsic (deg).",
        ),
    ] = None,
    translation_error_cm: Annotated[
        float | None,
        typer.Option(
            "--translation-error-cm",
            min=0.0,
            max=100.0,
            help="Translation error of the second LiDAR's recorded extrinsic (cm).",
        ),
    ] = None,
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
    seed: SeedOption = None,
    fmt: FormatOption = None,
    overwrite: OverwriteFlag = False,
) -> None:
    """Write a calibration session of two non-overlapping LiDARs and its truth (OUT.truth.json)."""

    def job() -> None:
        from syncaudit.simulate.calib_config import DEFAULT_MOUNT
        from syncaudit.simulate.calib_session import simulate_calib_session, truth_path
        from syncaudit.writers.log_writer import log_target

        if beams is not None and beams not in BEAMS:
            raise UsageError(f"--beams must be one of {'|'.join(map(str, BEAMS))}, got {beams}")
        choices = {
            "--mount": (mount, MOUNTS),
            "--motion": (motion, MOTIONS),
            "--organized": (organized, ORGANIZED),
            "--tf-chain": (tf_chain, TF_CHAINS),
            "--odometry": (odometry, ODOMETRY),
            "--scene": (scene, SCENES),
        }
        chosen = {
            option.removeprefix("--").replace("-", "_"): _choice(option, value, allowed)
            for option, (value, allowed) in choices.items()
            if value is not None
        }
        if degenerate:
            if chosen.get("scene", "yard") not in ("yard", "ground_and_wall"):
                raise UsageError(f"--degenerate conflicts with --scene {chosen['scene']}")
            chosen["scene"] = "ground_and_wall"
        preset = {
            "beams": beams,
            "range_noise_m": range_noise_m,
            "rear_rotation_error_deg": rotation_error_deg,
            "rear_translation_error_cm": translation_error_cm,
            "n_stops": stops,
            "seed": seed,
            "scans_per_stop": scans_per_stop,
            "turning_scans": turning_scans,
        }
        given = {name: value for name, value in preset.items() if value is not None}
        log_format = _format(out, fmt)
        target = log_target(out, log_format)
        config = _calib_config(config_file, {**chosen, **given})
        with output_set(overwrite=overwrite) as outputs:
            simulate_calib_session(
                target,
                config,
                fmt=log_format,
                overwrite=overwrite,
                outputs=outputs,
            )
        where = chosen.get("mount", DEFAULT_MOUNT) if config_file is None else config_file.name
        line = (
            f"wrote {target} ({config.motion}, {config.n_stops} stops, "
            f"{config.lidars[0].beams}-beam LiDARs {where}, {config.scene.kind}), "
            f"truth {truth_path(target)}"
        )
        emit(lambda: print(line))

    run(job)


_PRESET_OPTIONS: dict[str, str] = {
    "mount": "--mount",
    "beams": "--beams",
    "organized": "--organized",
    "range_noise_m": "--range-noise-m",
    "rear_rotation_error_deg": "--rotation-error-deg",
    "rear_translation_error_cm": "--translation-error-cm",
}
"""Options that build the LiDARs from a mount preset (a config file lists its LiDARs)."""


def _calib_config(config_file: Path | None, settings: dict[str, Any]) -> CalibSceneConfig:
    """The session: `calib_scene_config` of the options given, or the config file's session
    with the options given over it. The options' defaults are the config's.

    Raises:
        UsageError: an option out of range or not applying (exit 64, worded in options).
        ConfigError: the config file unreadable or invalid (naming the file).
    """
    from syncaudit.config import load_model
    from syncaudit.simulate.calib_config import CalibSceneConfig, calib_scene_config

    base = (
        None
        if config_file is None
        else load_model(config_file, CalibSceneConfig, what="calibration session config")
    )
    motion = settings.get("motion", "turntable" if base is None else base.motion)
    turntable_only = {"--scans-per-stop": "scans_per_stop", "--turning-scans": "turning_scans"}
    given = [option for option, name in turntable_only.items() if name in settings]
    if motion == "drive" and given:
        raise UsageError(f"{' and '.join(given)} only apply to --motion turntable")
    extra = {name: settings.pop(name) for name in turntable_only.values() if name in settings}
    try:
        if base is None:
            config = calib_scene_config(**settings)
            return CalibSceneConfig.model_validate({**config.model_dump(), **extra})
        presets = [option for name, option in _PRESET_OPTIONS.items() if name in settings]
        if presets:
            raise UsageError(
                f"{', '.join(presets)}: the LiDARs come from --config {config_file}; set them there"
            )
        data = {**base.model_dump(), **extra}
        for name in ("seed", "n_stops", "motion", "tf_chain", "odometry"):
            if name in settings:
                data[name] = settings[name]
        if "scene" in settings:
            data["scene"] = {**data["scene"], "kind": settings["scene"]}
        return CalibSceneConfig.model_validate(data)
    except ConfigError as exc:
        raise _usage(exc) from None
