"""`syncaudit rig`: a starter rig file guessed from a log."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from syncaudit.cli.common import (
    LidarMetadataOption,
    LogArgument,
    OverwriteFlag,
    app,
    emit,
    local_paths,
    log_location,
    output_set,
    run,
)


def _write_stdout(text: str) -> None:
    sys.stdout.write(text)


@app.command(short_help="Write a starter rig file guessed from a log.")
def rig(
    log: LogArgument,
    out: Annotated[
        Path | None, typer.Option("--output", "-o", help="Write the rig here (default: stdout).")
    ] = None,
    overwrite: OverwriteFlag = False,
    lidar_metadata: LidarMetadataOption = None,
) -> None:
    """Write a starter rig guessed from the log: every guess and TODO commented."""

    source = log_location(log)

    def job() -> None:
        with output_set(overwrite=overwrite, inputs=local_paths(source), targets=(out,)) as outputs:
            from syncaudit.audit.rig_guess import starter_rig_yaml

            text = starter_rig_yaml(source, lidar_metadata)
            if out is not None:
                from syncaudit.writers.provenance import COMMENT_MARK

                outputs.write_text(out, COMMENT_MARK + text)
        if out is None:
            emit(lambda: _write_stdout(text))

    run(job)
