"""`syncaudit audit`: the synchronisation method per camera, with its outputs."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

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
    output_set,
    print_json,
    run,
    stdout_console,
)


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
            "--check-crc", help="Verify every MCAP chunk's CRC (a quarter to a third slower)."
        ),
    ] = False,
) -> None:
    """Audit LiDAR-camera sync per camera (Eq 1-6), the recommended delay and the verdict."""

    def job() -> None:
        pairings = _pairings_target(pairings_out) if pairings_out else None
        with output_set(
            overwrite=overwrite, inputs=(log, rig), targets=(json_out, html_out, csv_out)
        ) as outputs:
            if pairings is not None:
                outputs.add(pairings, kind="dir" if pairings.suffix == "" else "file")
            from syncaudit.audit import audit_log
            from syncaudit.rig import load_rig

            result = audit_log(log, load_rig(rig) if rig else None, jobs=jobs, check_crc=check_crc)
            data = result.to_dict()
            if json_out:
                outputs.write_text(json_out, json_text(data))
            if pairings is not None:
                from syncaudit.writers.pairings import write_pairings

                with outputs.writing(pairings):
                    write_pairings(result, pairings, overwrite=overwrite, outputs=outputs)
            if html_out:
                from syncaudit.report.html import render_audit_html

                outputs.write_text(html_out, render_audit_html(result))
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

            raise GateFailedError(f"{log}: sync audit failed ({data['verdict']})")

    run(job)


def _pairings_target(path: Path) -> Path:
    """Where `--pairings PATH` is written (`p.db3` -> the bag folder `p`); usage error if unknown."""
    from syncaudit.errors import ConfigError, UsageError
    from syncaudit.writers.log_writer import infer_format, log_target

    try:
        return log_target(path, infer_format(path))
    except ConfigError as exc:
        raise UsageError(f"--pairings: {exc}") from None
