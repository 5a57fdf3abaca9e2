"""`syncaudit gate` and `syncaudit fleet report`: thin commands over `syncaudit.fleet`."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from syncaudit.cli.common import OverwriteFlag, app, note, run, say, stderr_console
from syncaudit.errors import ConfigError, UsageError

if TYPE_CHECKING:
    from syncaudit.fleet.gate import GateOptions

MAX_WARNING_LINES = 10


def _escape(text: str) -> str:
    """Text shown through rich markup as written (a path may hold `[...]`)."""
    from rich.markup import escape

    return escape(text)


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
            console=stderr_console(),
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
        skipped = " (unchanged, from the database)" if log.skipped else ""
        error = f": {log.error}" if log.error else ""
        say(f"[{done}/{total}] {log.verdict} {log.path}{skipped}{error}")

    return line, lambda: None


@app.command(
    short_help="Judge many logs against a policy (CI gate).",
)
def gate(
    inputs: Annotated[
        list[str],
        typer.Argument(
            metavar="LOG",
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
    accept_bad: Annotated[
        bool,
        typer.Option(
            "--accept-bad",
            help="With --init: write the policy although the known-good logs fail the "
            "default thresholds, have no camera or disagree on the clock (warned).",
        ),
    ] = False,
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
    tries: Annotated[int, typer.Option("--tries", help="Tries per log when its worker dies.")] = 2,
    force: Annotated[
        bool, typer.Option("--force", help="Judge again logs already in the database.")
    ] = False,
    overwrite: OverwriteFlag = False,
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

    def job() -> int:
        if jobs is not None and jobs < 1:
            raise UsageError("--jobs must be at least 1")
        if timeout <= 0 or tries < 1:
            raise UsageError("--timeout must be positive and --tries at least 1")
        if init:
            _init(inputs, _init_target(output, policy), overwrite, jobs, timeout, accept_bad)
            return 0
        if policy is None:
            raise UsageError("missing --policy (write one with --init LOG... -o policy.yaml)")
        if output is not None:
            raise UsageError("-o/--output is for --init; use --junit/--summary/--json-out")
        from syncaudit.fleet.gate import GateOptions

        options = GateOptions(
            db=None if no_db else db,
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
            policy_path=policy,
        )
        return _gate(inputs, policy, options)

    raise typer.Exit(run(job))


def _init_target(output: Path | None, policy: Path | None) -> Path:
    """The policy file `--init` writes: it needs -o and takes no --policy."""
    if output is None:
        raise UsageError("--init needs -o/--output (the policy file to write)")
    if policy is not None:
        raise UsageError("--init writes a policy: it does not take --policy")
    return output


fleet_app = typer.Typer(
    help="Fleet results: dashboards and exports from the results database.",
    no_args_is_help=True,
)
app.add_typer(fleet_app, name="fleet", short_help="Fleet dashboards and exports.")


@fleet_app.command("report", short_help="Dashboard and tables of the results database.")
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
    overwrite: OverwriteFlag = False,
) -> None:
    """Dashboard of Eq. 5 error, delays and t1..t4 per vehicle and camera over time."""

    def job() -> None:
        if html is None and parquet is None and csv is None:
            raise UsageError("nothing to do: give --html, --parquet and/or --csv")
        _need_duckdb()
        from syncaudit.fleet.dashboard import write_report

        write_report(db, html_dir=html, parquet=parquet, csv=csv, overwrite=overwrite)

    run(job)


def _need_duckdb() -> None:
    """The results database needs the `fleet` extra: say so (exit 64) rather than crash."""
    try:
        import duckdb  # noqa: F401
    except ImportError:
        raise UsageError(
            "the results database needs DuckDB: pip install 'syncaudit[fleet]' (or pass --no-db)"
        ) from None


def _init(
    inputs: list[str],
    output: Path,
    overwrite: bool,
    jobs: int | None,
    timeout: float,
    accept_bad: bool = False,
) -> None:
    from syncaudit.errors import GateFailedError
    from syncaudit.fleet.gate import GateOptions, make_executor
    from syncaudit.fleet.gate_outputs import OVERWRITE_HINT
    from syncaudit.fleet.init_policy import init_policy_yaml, learn_policy
    from syncaudit.fleet.init_review import init_problems
    from syncaudit.fleet.inputs import discover
    from syncaudit.fleet.job import JobOptions
    from syncaudit.fleet.policy import Policy
    from syncaudit.writers.outputs import OutputSet
    from syncaudit.writers.provenance import COMMENT_MARK

    protected = [i for i in inputs if "://" not in i]
    with OutputSet(overwrite=overwrite, inputs=protected, overwrite_hint=OVERWRITE_HINT) as out:
        out.claim(output)  # checked before any work
        found = discover(inputs, Policy())
        if not found.jobs:
            raise ConfigError("--init found no log in " + " ".join(inputs))
        executor, audit_jobs = make_executor(
            GateOptions(jobs=jobs, timeout_s=timeout), len(found.jobs)
        )
        outcomes = list(executor.run(found.jobs, JobOptions(audit_jobs=audit_jobs)))
        bad = [o for o in outcomes if not o.ok]
        for outcome in bad:
            note(f"[yellow]skipped:[/] {_escape(f'{outcome.job.path}: {outcome.error}')}")
        if len(bad) == len(outcomes):
            from syncaudit.errors import LogReadError

            raise LogReadError("--init: no log could be audited")
        problems = init_problems(outcomes)
        for line in problems:
            note(f"[bold red]WARNING:[/] {_escape(line)}")
        if problems and not accept_bad:
            raise GateFailedError(
                f"--init: {len(problems)} reason(s) to doubt the known-good logs (above): "
                "no policy written; drop those logs, or pass --accept-bad to write it anyway"
            )
        for line in learn_policy(outcomes)[1]:
            note(_escape(f"learnt {line}"))
        out.write_text(output, COMMENT_MARK + init_policy_yaml(outcomes, problems))
    note(_escape(f"policy from {len(outcomes) - len(bad)} log(s) written to {output}"))


def _gate(inputs: list[str], policy_path: Path, options: GateOptions) -> int:
    """Run the gate with its progress on stderr; the exit code its verdicts make."""
    from syncaudit.fleet.gate import run_gate
    from syncaudit.fleet.policy import load_policy

    policy = load_policy(policy_path)
    if options.db is not None:
        _need_duckdb()
    update, finish = _progress_printer()
    try:
        result = run_gate(inputs, policy, options, progress=update)
    finally:
        finish()
    for line in result.warnings[:MAX_WARNING_LINES]:
        note(f"[yellow]warning:[/] {_escape(line)}")
    if len(result.warnings) > MAX_WARNING_LINES:
        note(
            f"[yellow]warning:[/] ... and {len(result.warnings) - MAX_WARNING_LINES} more "
            "log(s) without a vehicle id (all listed in --summary / --json-out)"
        )
    counts = {
        v: sum(log.verdict == v for log in result.logs) for v in ("pass", "warn", "fail", "error")
    }
    note(f"gate: {len(result.logs)} log(s): " + ", ".join(f"{n} {v}" for v, n in counts.items()))
    return result.exit_code
