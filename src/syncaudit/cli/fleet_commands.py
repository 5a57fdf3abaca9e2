"""`syncaudit gate` and `syncaudit fleet report`: thin commands over `syncaudit.fleet`."""

from __future__ import annotations

import os
import sys
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from syncaudit.cli.startup import resume_gc
from syncaudit.errors import ConfigError, Interrupted, OutputError, SyncauditError, UsageError

if TYPE_CHECKING:
    from rich.console import Console

EXIT_USAGE = UsageError.exit_code
EXIT_INTERNAL = 70
MAX_WARNING_LINES = 10


@cache
def _stderr() -> Console:
    """The rich console on stderr, made on first use (`syncaudit --help` stays light)."""
    from rich.console import Console

    return Console(stderr=True, soft_wrap=True)


def _escape(text: str) -> str:
    """Text shown through rich markup as written (a path may hold `[...]`)."""
    from rich.markup import escape

    return escape(text)


def _fail(code: int, message: str) -> typer.Exit:
    for line in message.splitlines():
        typer.echo(f"error: {line}", err=True)
    return typer.Exit(code)


def _guarded(body: Any) -> Any:
    """Known errors: their lines and exit codes; anything else: exit 70, never a traceback."""
    resume_gc()  # the console script's start-up pause (syncaudit.cli.startup)
    try:
        return body()
    except typer.Exit:
        raise
    except SyncauditError as exc:
        raise _fail(exc.exit_code, str(exc)) from None
    except (KeyboardInterrupt, Interrupted):
        raise _fail(130, "interrupted") from None
    except OSError as exc:
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        raise _fail(OutputError.exit_code, f"{where}{exc.strerror or exc}") from None
    except Exception as exc:
        if os.environ.get("SYNCAUDIT_DEBUG"):
            raise
        raise _fail(
            EXIT_INTERNAL,
            f"internal error: {type(exc).__name__}: {exc} (set SYNCAUDIT_DEBUG=1 for a traceback)",
        ) from None


def _progress_printer(total_hint: int | None = None) -> tuple[Any, Any]:
    """(callback, finish): a rich bar with per-log status on a terminal, else one line per log."""
    if sys.stderr.isatty():
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
        )

        bar = Progress(
            TextColumn("gate"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TextColumn("{task.description}"),
            console=_stderr(),
            transient=False,
        )
        task = bar.add_task("", total=total_hint)
        bar.start()
        colours = {"pass": "green", "warn": "yellow", "fail": "red", "error": "red"}

        def update(log: Any, done: int, total: int) -> None:
            description = f"{log.verdict}: {_escape(log.path)}"
            # Drawn now, not at the next tick of the bar's refresh thread: the status line
            # printed below redraws the bar as last drawn (a loaded machine showed 0/? there).
            bar.update(task, completed=done, total=total, description=description, refresh=True)
            if log.verdict != "pass":
                bar.console.print(
                    f"[{colours[log.verdict]}]{log.verdict:5}[/] {_escape(log.path)}"
                    + (f" ({_escape(log.error)})" if log.error else ""),
                    highlight=False,
                )

        return update, bar.stop

    def line(log: Any, done: int, total: int) -> None:
        note = " (unchanged, from the database)" if log.skipped else ""
        error = f": {log.error}" if log.error else ""
        sys.stderr.write(f"[{done}/{total}] {log.verdict} {log.path}{note}{error}\n")
        sys.stderr.flush()

    return line, lambda: None


def register(app: typer.Typer) -> None:
    """Add `gate` and `fleet report` to the syncaudit command line."""

    @app.command()
    def gate(
        inputs: Annotated[
            list[str],
            typer.Argument(
                help="Logs, ROS 2 bag folders, directories (searched recursively), globs, "
                "or CSV/JSONL manifests (path, vehicle, rig, tags).",
                show_default=False,
            ),
        ],
        policy: Annotated[Path | None, typer.Option("--policy", help="Policy file (YAML).")] = None,
        init: Annotated[
            bool,
            typer.Option("--init", help="Write a policy from these known-good logs (to -o)."),
        ] = False,
        output: Annotated[
            Path | None,
            typer.Option("--output", "-o", help="With --init: the policy file to write."),
        ] = None,
        db: Annotated[
            Path, typer.Option("--db", help="Results database (DuckDB file), created if absent.")
        ] = Path("fleet.duckdb"),
        no_db: Annotated[
            bool, typer.Option("--no-db", help="Record nothing (no skipping of unchanged logs).")
        ] = False,
        junit: Annotated[Path | None, typer.Option("--junit", help="Write JUnit XML here.")] = None,
        summary: Annotated[
            Path | None, typer.Option("--summary", help="Write a Markdown summary here.")
        ] = None,
        json_out: Annotated[
            Path | None, typer.Option("--json-out", help="Write the JSON summary here.")
        ] = None,
        html: Annotated[
            Path | None,
            typer.Option("--html", help="Write per-log HTML reports and index.html here."),
        ] = None,
        jobs: Annotated[
            int | None, typer.Option("--jobs", "-j", help="Worker processes (default: cores).")
        ] = None,
        timeout: Annotated[
            float, typer.Option("--timeout", help="Per-log timeout in seconds.")
        ] = 3600.0,
        tries: Annotated[
            int, typer.Option("--tries", help="Tries per log when its worker dies.")
        ] = 2,
        force: Annotated[
            bool, typer.Option("--force", help="Judge again logs already in the database.")
        ] = False,
        overwrite: Annotated[
            bool, typer.Option("--overwrite", help="Replace existing output files.")
        ] = False,
        cluster: Annotated[
            str | None,
            typer.Option(
                "--cluster",
                help="Run the audits on this Dask scheduler (tcp://host:8786); "
                "needs syncaudit[cluster] here and on the workers.",
            ),
        ] = None,
    ) -> None:
        """Judge many logs against a policy: JUnit, summaries, reports, results database."""
        if jobs is not None and jobs < 1:
            raise _fail(EXIT_USAGE, "--jobs must be at least 1")
        if timeout <= 0 or tries < 1:
            raise _fail(EXIT_USAGE, "--timeout must be positive and --tries at least 1")
        if init:
            if output is None:
                raise _fail(EXIT_USAGE, "--init needs -o/--output (the policy file to write)")
            if policy is not None:
                raise _fail(EXIT_USAGE, "--init writes a policy: it does not take --policy")
            _guarded(lambda: _init(inputs, output, overwrite, jobs, timeout))
            return
        if policy is None:
            raise _fail(
                EXIT_USAGE, "missing --policy (write one with --init LOG... -o policy.yaml)"
            )
        if output is not None:
            raise _fail(EXIT_USAGE, "-o/--output is for --init; use --junit/--summary/--json-out")
        code = _guarded(
            lambda: _gate(
                inputs,
                policy,
                None if no_db else db,
                junit,
                summary,
                json_out,
                html,
                jobs,
                timeout,
                tries,
                force,
                overwrite,
                cluster,
            )
        )
        raise typer.Exit(code)

    fleet = typer.Typer(help="Fleet results: dashboards and exports from the results database.")

    @fleet.command("report")
    def report(
        db: Annotated[Path, typer.Option("--db", help="Results database (DuckDB file).")],
        html: Annotated[
            Path | None, typer.Option("--html", help="Write the dashboard (index.html) here.")
        ] = None,
        parquet: Annotated[
            Path | None, typer.Option("--parquet", help="Export the per-camera table as Parquet.")
        ] = None,
        csv: Annotated[
            Path | None, typer.Option("--csv", help="Export the per-camera table as CSV.")
        ] = None,
        overwrite: Annotated[
            bool, typer.Option("--overwrite", help="Replace existing outputs.")
        ] = False,
    ) -> None:
        """Dashboard of Eq. 5 error, delays and t1..t4 per vehicle and camera over time."""
        if html is None and parquet is None and csv is None:
            raise _fail(EXIT_USAGE, "nothing to do: give --html, --parquet and/or --csv")

        _need_duckdb()

        def body() -> None:
            from syncaudit.fleet.dashboard import write_report

            write_report(db, html_dir=html, parquet=parquet, csv=csv, overwrite=overwrite)

        _guarded(body)

    app.add_typer(fleet, name="fleet")


def _need_duckdb() -> None:
    """The results database needs the `fleet` extra: say so (exit 64) rather than crash."""
    try:
        import duckdb  # noqa: F401
    except ImportError:
        raise _fail(
            EXIT_USAGE,
            "the results database needs DuckDB: pip install 'syncaudit[fleet]' (or pass --no-db)",
        ) from None


def _init(
    inputs: list[str], output: Path, overwrite: bool, jobs: int | None, timeout: float
) -> None:
    from syncaudit.fleet.gate import GateOptions, make_executor
    from syncaudit.fleet.gate_outputs import OVERWRITE_HINT
    from syncaudit.fleet.init_policy import init_policy_yaml
    from syncaudit.fleet.inputs import discover
    from syncaudit.fleet.job import JobOptions
    from syncaudit.fleet.policy import Policy
    from syncaudit.writers.outputs import OutputSet

    protected = [i for i in inputs if "://" not in i]
    with OutputSet(overwrite=overwrite, inputs=protected, overwrite_hint=OVERWRITE_HINT) as out:
        out.add(output)  # checked before any work
        found = discover(inputs, Policy())
        if not found.jobs:
            raise ConfigError("--init found no log in " + " ".join(inputs))
        executor, audit_jobs = make_executor(
            GateOptions(jobs=jobs, timeout_s=timeout), len(found.jobs)
        )
        outcomes = list(executor.run(found.jobs, JobOptions(audit_jobs=audit_jobs)))
        bad = [o for o in outcomes if not o.ok]
        for outcome in bad:
            _stderr().print(
                f"[yellow]skipped:[/] {_escape(f'{outcome.job.path}: {outcome.error}')}",
                highlight=False,
            )
        if len(bad) == len(outcomes):
            from syncaudit.errors import LogReadError

            raise LogReadError("--init: no log could be audited")
        out.write_text(output, init_policy_yaml(outcomes))
    _stderr().print(
        f"policy from {len(outcomes) - len(bad)} log(s) written to {output}", highlight=False
    )


def _gate(
    inputs: list[str],
    policy_path: Path,
    db: Path | None,
    junit: Path | None,
    summary: Path | None,
    json_out: Path | None,
    html: Path | None,
    jobs: int | None,
    timeout: float,
    tries: int,
    force: bool,
    overwrite: bool,
    cluster: str | None = None,
) -> int:
    from syncaudit.fleet.gate import GateOptions, run_gate
    from syncaudit.fleet.policy import load_policy

    policy = load_policy(policy_path)
    if db is not None:
        _need_duckdb()
    options = GateOptions(
        db=db,
        junit=junit,
        summary=summary,
        json_out=json_out,
        html_dir=html,
        jobs=jobs,
        timeout_s=timeout,
        max_tries=tries,
        force=force,
        overwrite=overwrite,
        cluster=cluster,
        policy_path=policy_path,
    )
    update, finish = _progress_printer()
    try:
        run = run_gate(inputs, policy, options, progress=update)
    finally:
        finish()
    for line in run.warnings[:MAX_WARNING_LINES]:
        _stderr().print(f"[yellow]warning:[/] {_escape(line)}", highlight=False)
    if len(run.warnings) > MAX_WARNING_LINES:
        _stderr().print(
            f"[yellow]warning:[/] ... and {len(run.warnings) - MAX_WARNING_LINES} more "
            "log(s) without a vehicle id (all listed in --summary / --json-out)",
            highlight=False,
        )
    counts = {
        v: sum(log.verdict == v for log in run.logs) for v in ("pass", "warn", "fail", "error")
    }
    _stderr().print(
        f"gate: {len(run.logs)} log(s): " + ", ".join(f"{n} {v}" for v, n in counts.items()),
        highlight=False,
    )
    return run.exit_code
