"""`syncaudit audit`: the synchronisation method per camera, with its outputs."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from syncaudit.cli.common import (
    GateFlag,
    HtmlOption,
    JsonFlag,
    JsonOutOption,
    LidarCaptureOption,
    LidarMetadataOption,
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
    say,
    stdout_console,
)
from syncaudit.cli.startup import one_blas_thread

if TYPE_CHECKING:
    from syncaudit.audit.run import AuditResult
    from syncaudit.calib.result import CalibrationResult
    from syncaudit.rig import Rig
    from syncaudit.writers.outputs import OutputSet


@app.command(short_help="Audit LiDAR-camera sync per camera (Eq. 1-6).")
def audit(
    log: LogArgument,
    rig: RigOption = None,
    no_rig: Annotated[
        bool,
        typer.Option(
            "--no-rig",
            help="Guess topics and cameras from the log even where a LOG.rig.yaml lies beside it.",
        ),
    ] = False,
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
    calibration_any_log: Annotated[
        bool,
        typer.Option(
            "--calibration-any-log",
            help="Add the --calibration result even when it is of another log.",
        ),
    ] = False,
    gate: GateFlag = False,
    jobs: Annotated[
        int | None,
        typer.Option(
            "--jobs",
            "-j",
            min=1,
            help="Worker processes reading the log's chunks and analysing the cameras (default: cores).",
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
    lidar_metadata: LidarMetadataOption = None,
    lidar_capture: LidarCaptureOption = None,
) -> None:
    """Audit LiDAR-camera sync per camera (Eq 1-6), the recommended delay and the verdict."""

    source = log_location(log)

    def job() -> None:
        if rig is not None and no_rig:
            from syncaudit.errors import UsageError

            raise UsageError("--rig and --no-rig: give one")
        rig_path = rig or (None if no_rig else rig_beside(source))
        remote_rig = None if rig or no_rig else _remote_rig(source)
        targets = _Targets.of(json_out, pairings_out, html_out, csv_out, parquet_out)
        calibration = (
            _load_calibration(calibration_json, source, any_log=calibration_any_log)
            if calibration_json
            else None
        )
        with output_set(
            overwrite=overwrite,
            inputs=(
                *local_paths(source),
                rig_path,
                calibration_json,
                lidar_metadata,
                lidar_capture,
            ),
            targets=targets.files(),
        ) as outputs:
            targets.claim_pairings(outputs)
            result = _audit(
                source,
                remote_rig or rig_path,
                jobs=jobs,
                check_crc=check_crc,
                tables=not as_json,
                lidar=(lidar_metadata, lidar_capture),
            )
            data = result.to_dict()
            targets.write(outputs, result, data, calibration, overwrite=overwrite)
        _show(result, data, as_json=as_json)
        if gate and not result.passed:
            from syncaudit.errors import GateFailedError

            raise GateFailedError(f"{source}: sync audit failed ({data['verdict']})")

    run(job, imports=_import_audit)


@dataclass(frozen=True, slots=True)
class _Targets:
    """The files an audit writes, checked from the command line before any work."""

    json_out: Path | None
    pairings: Path | None
    """Where `--pairings` goes (a ROS 2 bag folder for `NAME.db3`)."""
    html: Path | None
    csv: Path | None
    parquet: tuple[Path, Path] | None
    """The per-frame table and the per-camera summary beside it."""

    @classmethod
    def of(
        cls,
        json_out: Path | None,
        pairings_out: Path | None,
        html: Path | None,
        csv: Path | None,
        parquet_out: Path | None,
    ) -> _Targets:
        """The targets of the options given; usage error (exit 64) or exit 8 now if wrong."""
        return cls(
            json_out=json_out,
            pairings=_pairings_target(pairings_out) if pairings_out else None,
            html=html,
            csv=csv,
            parquet=_parquet_targets(parquet_out) if parquet_out else None,
        )

    def files(self) -> tuple[Path | None, ...]:
        """Every single-file target (the pairings may be a folder: `claim_pairings`)."""
        return (self.json_out, self.html, self.csv, *(self.parquet or (None, None)))

    def claim_pairings(self, outputs: OutputSet) -> None:
        """Add the pairings log to the output set (a folder for a ROS 2 bag)."""
        if self.pairings is not None:
            outputs.claim(self.pairings, kind="dir" if self.pairings.suffix == "" else "file")

    def write(
        self,
        outputs: OutputSet,
        result: AuditResult,
        data: dict[str, Any],
        calibration: CalibrationResult | None,
        *,
        overwrite: bool,
    ) -> None:
        """Write every asked-for output of the audit into the output set."""
        if self.json_out:
            outputs.write_text(self.json_out, json_text(data))
        if self.pairings is not None:
            from syncaudit.writers.pairings import write_pairings

            with outputs.writing(self.pairings):
                write_pairings(result, self.pairings, overwrite=overwrite, outputs=outputs)
        if self.html:
            from syncaudit.report.report_page import render_report_html

            outputs.write_text(self.html, render_report_html(result, calibration))
        if self.parquet is not None:
            from syncaudit.writers.parquet import cameras_parquet, frames_parquet

            outputs.write_bytes(self.parquet[0], frames_parquet(result))
            outputs.write_bytes(self.parquet[1], cameras_parquet(result))
        if self.csv:
            from syncaudit.writers.frames_csv import frames_csv

            outputs.write_text(self.csv, frames_csv(result))


def rig_beside(source: str | Path) -> Path | None:
    """The rig `LOG.rig.yaml` beside a local log, as `gate` takes it (None for a URL or none).

    Said on stderr, so a user who meant the guess knows to pass `--no-rig`.
    """
    if not isinstance(source, Path):
        return None
    from syncaudit.audit.rig_beside import local_rig_beside

    beside = local_rig_beside(source)
    if beside is None:
        return None
    say(f"using rig {beside.name} beside the log (--rig to choose another, --no-rig to guess)")
    return beside


def _remote_rig(source: str | Path) -> Rig | None:
    """The rig beside a remote log (None for a local log, or none there), said on stderr."""
    if isinstance(source, Path):
        return None
    from syncaudit.audit.rig_beside import remote_rig_beside

    found = remote_rig_beside(source)
    if found.said:
        say(found.said)
    return found.rig


def _audit(
    log: str | Path,
    rig: Path | Rig | None,
    *,
    jobs: int | None,
    check_crc: bool,
    tables: bool,
    lidar: tuple[Path | None, Path | None] = (None, None),
) -> AuditResult:
    """The audit of `log`; the tables' modules are imported while the workers read."""
    from syncaudit.audit.run import audit_log
    from syncaudit.rig import load_rig

    return audit_log(
        log,
        load_rig(rig) if isinstance(rig, Path) else rig,
        jobs=jobs,
        check_crc=check_crc,
        meanwhile=_import_tables if tables else None,
        lidar_metadata=lidar[0],
        lidar_capture=lidar[1],
    )


def _show(result: AuditResult, data: dict[str, Any], *, as_json: bool) -> None:
    """The result on stdout: JSON, or the tables."""
    if as_json:
        print_json(data)
    else:
        from syncaudit.report.console import render_audit

        emit(lambda: render_audit(result, stdout_console()))


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
    """`--parquet F`: F and its per-camera summary; exit 64 now when pyarrow is missing."""
    from syncaudit.cli.common import require_extra
    from syncaudit.writers.parquet import cameras_path

    require_extra("pyarrow.parquet", extra="parquet", option="--parquet")
    return path, cameras_path(path)


def _load_calibration(path: Path, log: str | Path, *, any_log: bool) -> CalibrationResult:
    """A saved calibration result (`calib --json-out`) of `log`, for the combined report.

    One of another log is refused (exit 6) unless `any_log` (`report.calibration_log`).
    """
    import json

    from pydantic import ValidationError

    from syncaudit.calib.result import CalibrationResult
    from syncaudit.config import unique_pairs
    from syncaudit.errors import ConfigError, InputOpenError, SyncauditError
    from syncaudit.fleet.inputs import fingerprint
    from syncaudit.report.calibration_log import calibration_mismatch

    try:
        raw = path.read_bytes()
        result = CalibrationResult.model_validate_json(raw)
        tree = json.loads(raw, object_pairs_hook=unique_pairs)  # a key twice: which is meant?
    except OSError as exc:  # cannot be opened: exit 2, as any missing input
        raise InputOpenError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or "document"
        raise ConfigError(f"{path}: not a calibration result ({where}: {first['msg']})") from exc
    except ConfigError as exc:
        raise ConfigError(f"{path}: not a calibration result ({exc})") from None
    if not any_log:
        try:
            log_fp: str | None = fingerprint(log)
        except (OSError, SyncauditError):
            log_fp = None
        why = calibration_mismatch(tree, log, log_fp)
        if why is not None:
            raise ConfigError(f"{path}: {why}; pass --calibration-any-log to add it anyway")
    return result


def _pairings_target(path: Path) -> Path:
    """Where `--pairings PATH` is written (`p.db3` -> the bag folder `p`); usage error if unknown."""
    from syncaudit.errors import ConfigError, UsageError
    from syncaudit.writers.log_writer import infer_format, log_target

    try:
        return log_target(path, infer_format(path))
    except ConfigError as exc:
        raise UsageError(f"--pairings: {exc}") from None
