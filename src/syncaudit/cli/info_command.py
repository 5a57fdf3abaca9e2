"""`syncaudit info`: what a log holds, measured."""

from __future__ import annotations

from typing import Annotated

import typer

from syncaudit.cli.common import (
    JsonFlag,
    LidarCaptureOption,
    LidarMetadataOption,
    LogArgument,
    RigOption,
    app,
    emit,
    fail,
    log_location,
    print_json,
    run,
)
from syncaudit.cli.startup import one_blas_thread

CheckCrcFlag = Annotated[
    bool,
    typer.Option(
        "--check-crc",
        help="Verify every MCAP chunk's CRC; exit 3 (damaged) when any is bad, listing them.",
    ),
]


@app.command(short_help="Summarise a log: topics, LiDARs, cameras.")
def info(
    log: LogArgument,
    rig: RigOption = None,
    as_json: JsonFlag = False,
    lidar_metadata: LidarMetadataOption = None,
    lidar_capture: LidarCaptureOption = None,
    check_crc: CheckCrcFlag = False,
) -> None:
    """Summarise a log: topics, each LiDAR (measured RPM, drops, clock) and each camera.

    A LiDAR topic that `audit` could not read is printed as far as it was read, then
    `info` exits with the code `audit` would give. The log's health (truncation, damaged
    records and, with --check-crc, bad chunk CRCs) is in the output and the JSON's `health`.
    """

    def job() -> None:
        from syncaudit.audit.inspect import inspect_log
        from syncaudit.rig import load_rig

        report = inspect_log(
            log_location(log),
            load_rig(rig) if rig else None,
            partial=True,
            lidar_metadata=lidar_metadata,
            lidar_capture=lidar_capture,
            check_crc=check_crc,
        )
        if as_json:
            print_json(report.to_dict())
        else:
            from syncaudit.cli.common import stdout_console
            from syncaudit.report.console import render_info

            emit(lambda: render_info(report, stdout_console()))
        if report.error is not None:
            fail(" ".join(report.error.split()), report.exit_code)
        bad = (report.health or {}).get("bad_crc_chunks") or []
        if bad:
            from syncaudit.errors import LogReadError

            where = ", ".join(str(offset) for offset in bad[:10])
            more = f" (+{len(bad) - 10} more)" if len(bad) > 10 else ""
            fail(
                f"{report.path}: {len(bad)} MCAP chunk(s) fail their CRC, at byte {where}{more}",
                LogReadError.exit_code,
            )

    run(job, imports=_import_info)


def _import_info() -> None:
    """The modules `info` needs, imported while the collector is paused (see `run`), numpy
    with one OpenBLAS thread (the reading's parallelism is its worker processes)."""
    one_blas_thread()
    import syncaudit.audit.inspect
    import syncaudit.rig  # noqa: F401
