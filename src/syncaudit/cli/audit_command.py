"""`syncaudit audit`: the synchronisation method per camera, with its outputs."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from syncaudit.cli.common import (
    GateFlag,
    HtmlOption,
    JsonFlag,
    JsonOutOption,
    LogArgument,
    OverwriteFlag,
    RigOption,
    app,
    emit,
    json_text,
    local_paths,
    log_location,
    output_set,
    print_json,
    run,
    stdout_console,
)
from syncaudit.cli.startup import one_blas_thread

if TYPE_CHECKING:
    from syncaudit.calib.result import CalibrationResult


@app.command()
def audit(
    log: LogArgument,
    rig: RigOption = None,
    as_json: JsonFlag = False,
    json_out: JsonOutOption = None,
    pairings_out: Annotated[
        Path | None,
        typer.Option(
            "--pairings",
            help="Write each frame's corrected timing (FramePairing) to a log: .mcap, .bag, "
            "or a ROS 2 bag folder (a name without suffix, or NAME.db3 -> folder NAME).",
        ),
    ] = None,
    html_out: HtmlOption = None,
    csv_out: Annotated[
        Path | None, typer.Option("--csv", help="Write the per-frame table as CSV here.")
    ] = None,
    parquet_out: Annotated[
        Path | None,
        typer.Option(
            "--parquet",
            help="Write the per-frame table here as Parquet, and the per-camera summary "
            "beside it (F.cameras.parquet); needs syncaudit[parquet].",
        ),
    ] = None,
    calibration_json: Annotated[
        Path | None,
        typer.Option(
            "--calibration",
            help="A `calib --json-out` result of the same log to add to the --html report.",
        ),
    ] = None,
    gate: GateFlag = False,
    jobs: Annotated[
        int | None,
        typer.Option(
            "--jobs", "-j", min=1, help="Worker processes for MCAP chunks (default: cores)."
        ),
    ] = None,
    overwrite: OverwriteFlag = False,
    check_crc: Annotated[
        bool,
        typer.Option(
            "--check-crc",
            help="Verify every MCAP chunk's CRC (a quarter to a third slower) and every "
            "ROS 1 lz4 chunk's checksums.",
        ),
    ] = False,
) -> None:
    """Audit LiDAR-camera sync per camera (Eq 1-6), the recommended delay and the verdict."""

    source = log_location(log)

    def job() -> None:
        pairings = _pairings_target(pairings_out) if pairings_out else None
        parquet = _parquet_targets(parquet_out) if parquet_out else (None, None)
        calibration = _load_calibration(calibration_json) if calibration_json else None
        with output_set(
            overwrite=overwrite,
            inputs=(*local_paths(source), rig, calibration_json),
            targets=(json_out, html_out, csv_out, *parquet),
        ) as outputs:
            if pairings is not None:
                outputs.add(pairings, kind="dir" if pairings.suffix == "" else "file")
            from syncaudit.audit.run import audit_log
            from syncaudit.rig import load_rig

            result = audit_log(
                source,
                load_rig(rig) if rig else None,
                jobs=jobs,
                check_crc=check_crc,
                meanwhile=None if as_json else _import_tables,
            )
            data = result.to_dict()
            if json_out:
                outputs.write_text(json_out, json_text(data))
            if pairings is not None:
                from syncaudit.writers.pairings import write_pairings

                with outputs.writing(pairings):
                    write_pairings(result, pairings, overwrite=overwrite, outputs=outputs)
            if html_out:
                from syncaudit.report.html import render_report_html

                outputs.write_text(html_out, render_report_html(result, calibration))
            if parquet[0] is not None and parquet[1] is not None:
                from syncaudit.writers.parquet import cameras_parquet, frames_parquet

                outputs.write_bytes(parquet[0], frames_parquet(result))
                outputs.write_bytes(parquet[1], cameras_parquet(result))
            if csv_out:
                from syncaudit.writers.frames_csv import frames_csv

                outputs.write_text(csv_out, frames_csv(result))
        if as_json:
            print_json(data)
        else:
            from syncaudit.report.console import render_audit

            emit(lambda: render_audit(result, stdout_console()))
        if gate and not result.passed:
            from syncaudit.errors import GateFailedError

            raise GateFailedError(f"{source}: sync audit failed ({data['verdict']})")

    run(job, imports=_import_audit)


def _import_audit() -> None:
    """The modules every audit needs, imported while the collector is paused (see `run`),
    numpy with one OpenBLAS thread (the audit's parallelism is its reader processes)."""
    one_blas_thread()
    # Import statements, not importlib: `python -X importtime` names only those.
    import syncaudit.audit.run
    import syncaudit.rig  # noqa: F401


def _import_tables() -> None:
    """What prints the result's tables (rich: ~20 ms), imported while workers read."""
    import syncaudit.report.console  # noqa: F401


def _parquet_targets(path: Path) -> tuple[Path, Path]:
    """`--parquet F`: F and its per-camera summary; exit 8 now when pyarrow is missing."""
    from syncaudit.writers.parquet import cameras_path, require_pyarrow

    require_pyarrow()
    return path, cameras_path(path)


def _load_calibration(path: Path) -> CalibrationResult:
    """A saved calibration result (`calib --json-out`), for the combined report."""
    from pydantic import ValidationError

    from syncaudit.calib.result import CalibrationResult
    from syncaudit.errors import ConfigError

    try:
        return CalibrationResult.model_validate_json(path.read_bytes())
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read ({exc.strerror or exc})") from exc
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or "document"
        raise ConfigError(f"{path}: not a calibration result ({where}: {first['msg']})") from exc


def _pairings_target(path: Path) -> Path:
    """Where `--pairings PATH` is written (`p.db3` -> the bag folder `p`); usage error if unknown."""
    from syncaudit.errors import ConfigError, UsageError
    from syncaudit.writers.log_writer import infer_format, log_target

    try:
        return log_target(path, infer_format(path))
    except ConfigError as exc:
        raise UsageError(f"--pairings: {exc}") from None
