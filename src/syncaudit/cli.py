"""The `syncaudit` command line: thin verbs over the library API."""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, TypeVar

import typer
from rich.console import Console

from syncaudit.errors import SyncauditError

app = typer.Typer(
    name="syncaudit",
    help="Audit LiDAR-camera synchronisation and LiDAR extrinsics in MCAP, ROS 2 and ROS 1 logs.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
out = Console()
err = Console(stderr=True, soft_wrap=True)

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
        err.print(f"[red]error:[/] {exc}", highlight=False)
        raise typer.Exit(exc.exit_code) from None
    except KeyboardInterrupt:
        raise typer.Exit(130) from None
    except Exception as exc:
        if os.environ.get("SYNCAUDIT_DEBUG"):
            raise
        err.print(
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
            render_info(report, out)

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
    csv_out: Annotated[
        Path | None, typer.Option("--csv", help="Write the per-frame table as CSV here.")
    ] = None,
    gate: Annotated[
        bool, typer.Option("--gate", help="Exit 10 when a camera crosses a threshold (CI gate).")
    ] = False,
) -> None:
    """Audit LiDAR-camera sync: Eq. 1-6 per camera, recommended delay, threshold verdict."""
    from syncaudit.audit import audit_log
    from syncaudit.errors import GateFailedError
    from syncaudit.report.console import render_audit
    from syncaudit.rig import load_rig
    from syncaudit.writers.atomic import write_atomic, write_text_atomic

    def job() -> None:
        result = audit_log(log, load_rig(rig) if rig else None)
        data = result.to_dict()
        if json_out:
            write_text_atomic(json_out, json.dumps(data, indent=2, allow_nan=False) + "\n")
        if csv_out:
            frames = result.frames()
            write_atomic(csv_out, lambda handle: frames.to_csv(handle, index=False))
        if as_json:
            _print_json(data)
        else:
            render_audit(result, out)
        if gate and not result.passed:
            raise GateFailedError(f"{log}: sync audit failed ({data['verdict']})")

    _run(job)


def main() -> None:
    """Console-script entry point."""
    app()


if __name__ == "__main__":
    main()
