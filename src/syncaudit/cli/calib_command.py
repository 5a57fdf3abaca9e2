"""`syncaudit calib`: calibrate non-overlapping LiDARs and validate recorded extrinsics."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from syncaudit.cli.common import (
    HtmlOption,
    JsonFlag,
    JsonOutOption,
    OverwriteFlag,
    app,
    emit,
    json_text,
    output_set,
    print_json,
    run,
    stdout_console,
)
from syncaudit.errors import UsageError


def _topics(value: str | None) -> list[str] | None:
    """`--topics A,B` as a list; a usage error for fewer than two or repeated topics."""
    if value is None:
        return None
    topics = [t.strip() for t in value.split(",") if t.strip()]
    if len(topics) < 2:
        raise UsageError(f"--topics needs two or more topics separated by commas, got {value!r}")
    if len(set(topics)) != len(topics):
        raise UsageError(f"--topics names a topic twice: {value!r}")
    return topics


@app.command(short_help="Calibrate LiDARs and check recorded extrinsics.")
def calib(
    log: Annotated[Path, typer.Argument(help="Log with PointCloud2 of two or more LiDARs.")],
    config_file: Annotated[
        Path | None,
        typer.Option("--config", help="Calibration config (YAML/TOML/JSON; keys in README)."),
    ] = None,
    extrinsics: Annotated[
        Path | None,
        typer.Option(
            "--extrinsics",
            help="Recorded extrinsics file to validate (default: /tf_static in the log).",
        ),
    ] = None,
    topics: Annotated[
        str | None,
        typer.Option("--topics", help="Comma-separated PointCloud2 topics (default: all)."),
    ] = None,
    as_json: JsonFlag = False,
    json_out: JsonOutOption = None,
    html_out: HtmlOption = None,
    gate: Annotated[
        bool,
        typer.Option("--gate", help="Exit 10 when validation fails or calibration is impossible."),
    ] = False,
    overwrite: OverwriteFlag = False,
) -> None:
    """Calibrate non-overlapping LiDARs and validate the recorded extrinsics (method B)."""

    def job() -> None:
        topic_list = _topics(topics)
        with output_set(
            overwrite=overwrite,
            inputs=(log, config_file, extrinsics),
            targets=(json_out, html_out),
        ) as outputs:
            result = _calibrate(log, config_file, extrinsics, topic_list)
            if json_out:
                outputs.write_text(json_out, json_text(_with_log_identity(result, log)))
            if html_out:
                from syncaudit.report.report_page import render_calibration_html

                outputs.write_text(html_out, render_calibration_html(result))
        if as_json:
            print_json(result.to_json_dict())
        else:
            from syncaudit.report.calib_section import render_calibration

            emit(lambda: render_calibration(result, stdout_console()))
        if gate and not result.passed:
            from syncaudit.errors import GateFailedError

            why = result.reason or "recorded extrinsics outside the limits"
            raise GateFailedError(f"{log}: calibration check failed: {why}")

    run(job)


def _with_log_identity(result: Any, log: Path) -> dict[str, Any]:
    """The result's JSON with its log's size and fingerprint (what `audit --calibration` checks)."""
    from syncaudit.fleet.inputs import fingerprint
    from syncaudit.report.calibration_log import IDENTITY_KEY, log_identity

    files = sorted(p for p in log.rglob("*") if p.is_file()) if log.is_dir() else [log]
    size_bytes = sum(p.stat().st_size for p in files)
    return {**result.to_json_dict(), IDENTITY_KEY: log_identity(size_bytes, fingerprint(log))}


def _calibrate(
    log: Path, config_file: Path | None, extrinsics: Path | None, topics: list[str] | None
) -> Any:
    """Load the config, apply the command-line overrides and run the calibration."""
    from syncaudit.cli.common import require_extra
    from syncaudit.errors import ConfigError

    for module in ("small_gicp", "gtsam"):  # before any work: exit 64 naming the extra
        require_extra(module, extra="calib", option="LiDAR calibration")
    from syncaudit.calib import CalibConfig, calibrate_log, load_config

    config: CalibConfig = load_config(config_file, CalibConfig) if config_file else CalibConfig()
    updates: dict[str, object] = {}
    if extrinsics is not None:
        updates["extrinsics_file"] = extrinsics
    if topics is not None:
        updates["lidar_topics"] = topics
    if updates:
        try:
            config = CalibConfig.model_validate({**config.model_dump(), **updates})
        except ConfigError as exc:
            flag = "--topics" if topics is not None else "--extrinsics"
            raise UsageError(f"{flag}: {str(exc).split(': ', 1)[-1]}") from None
    return calibrate_log(log, config)
