"""The gate driver: find logs, skip unchanged ones, audit the rest, judge, record, report.

Only this process writes the database and the outputs; workers (local processes or a
cluster) return plain outcomes. Exit code: 3 when some log could not be read, else 10
when some log fails the policy, else 0 (an unread log is an unknown verdict, which is
worse than a known failure, so 3 wins).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from syncaudit import __version__
from syncaudit.errors import GateFailedError, LogReadError, OutputError, SyncauditError
from syncaudit.fleet.checks import evaluate, verdict
from syncaudit.fleet.database import ResultsDB
from syncaudit.fleet.executor import DEFAULT_MAX_TRIES, DEFAULT_TIMEOUT_S, Executor, LocalExecutor
from syncaudit.fleet.gate_outputs import GateOutputs
from syncaudit.fleet.inputs import LogJob, discover, file_fingerprint, fingerprint
from syncaudit.fleet.job import JobOptions, LogOutcome
from syncaudit.fleet.log_pages import (
    render_error_page,
    render_log_page,
    report_file_name,
    report_name,
)
from syncaudit.fleet.policy import Policy
from syncaudit.fleet.record import JudgedLog, display_path, log_key
from syncaudit.fleet.remote_job import run_any_log_job
from syncaudit.logs.parallel import default_jobs
from syncaudit.remote.urls import is_url, public_url

DB_BATCH_LOGS = 32
DB_BATCH_S = 5.0


@dataclass(frozen=True, slots=True)
class GateOptions:
    """Where results go and how the audits run."""

    db: Path | None = None
    junit: Path | None = None
    summary: Path | None = None
    json_out: Path | None = None
    html_dir: Path | None = None
    jobs: int | None = None
    timeout_s: float = DEFAULT_TIMEOUT_S
    max_tries: int = DEFAULT_MAX_TRIES
    force: bool = False
    overwrite: bool = False
    cluster: str | None = None
    """Dask scheduler address (`tcp://host:8786`): audits run there, not here."""
    policy_path: Path | None = None
    """The policy file, never to be written over by an output."""


@dataclass(slots=True)
class GateRun:
    """The verdicts of a run, sorted by path, and the exit code they make."""

    logs: list[JudgedLog] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    """Logs judged without a vehicle id although the policy refers to vehicles."""

    @property
    def exit_code(self) -> int:
        """3 some log unread, 10 some log failed, 0 all passed (or only warnings)."""
        verdicts = {log.verdict for log in self.logs}
        if "error" in verdicts:
            return LogReadError.exit_code
        if "fail" in verdicts:
            return GateFailedError.exit_code
        return 0


Progress = Callable[[JudgedLog, int, int], None]
"""Called for each verdict with (verdict, done so far, total)."""


def check_targets(options: GateOptions) -> None:
    """Refuse a results database that cannot be written before any work is done.

    The file outputs are checked by `GateOutputs` (all of them, before any work).
    """
    if options.db is not None:
        if options.db.is_dir():
            raise OutputError(f"{options.db}: is a directory (--db needs a DuckDB file)")
        if not options.db.parent.is_dir():
            raise OutputError(f"{options.db}: folder {options.db.parent} does not exist")


def plan_outputs(inputs: list[str], options: GateOptions) -> GateOutputs:
    """Every file output of the run, checked now (exists without --overwrite: exit 8)."""
    check_targets(options)
    protected: list[str | Path | None] = [i for i in inputs if not is_url(i)]
    protected.append(options.policy_path)
    return GateOutputs(
        junit=options.junit,
        summary=options.summary,
        json_out=options.json_out,
        html_dir=options.html_dir,
        overwrite=options.overwrite,
        inputs=protected,
    )


def _judge(
    outcome: LogOutcome, policy: Policy, fp: str, rig_fp: str | None, policy_fp: str
) -> JudgedLog:
    checks = evaluate(outcome, policy, outcome.job.vehicle)  # the policy's one evaluation
    judged = verdict(outcome, checks)
    draft = outcome.report_draft
    job = outcome.job
    if is_url(job.path):  # the database and outputs never keep a query string (tokens)
        job = LogJob(public_url(job.path), job.vehicle, job.rig_path, job.tags, job.source)
    return JudgedLog(
        job=job,
        key=log_key(fp, job.path, __version__, rig_fp, policy_fp),
        fingerprint=fp,
        rig_fingerprint=rig_fp,
        policy_fingerprint=policy_fp,
        tool_version=__version__,
        verdict=judged,
        checks=checks,
        audit=outcome.audit,
        start_ns=outcome.start_ns,
        error=outcome.error,
        error_code=outcome.error_code,
        attempts=outcome.attempts,
        elapsed_s=outcome.elapsed_s,
        html=None if draft is None else render_log_page(draft, checks, judged, outcome.audit),
        camera_count=None if outcome.audit is None else len(outcome.audit.get("cameras", [])),
        remote_read=outcome.remote_read,
        duration_s=outcome.duration_s,
        container=outcome.container,
        health=None if outcome.audit is None else outcome.audit.get("health"),
        advice={
            cam["camera"]: cam["recommendation"]
            for cam in (outcome.audit or {}).get("cameras", [])
            if isinstance(cam.get("recommendation"), dict)
        },
    )


def _stored(path: str) -> str:
    """How a log is named in the database: absolute path, or URL without query string."""
    return public_url(path) if is_url(path) else os.path.abspath(path)


def _error_log(job: LogJob, error: SyncauditError, policy_fp: str) -> JudgedLog:
    return JudgedLog(
        job=job,
        key=log_key("missing", _stored(job.path), __version__, None, policy_fp),
        fingerprint="-",
        rig_fingerprint=None,
        policy_fingerprint=policy_fp,
        tool_version=__version__,
        verdict="error",
        error=str(error).splitlines()[0],
        error_code=error.exit_code,
    )


def make_executor(
    options: GateOptions, pending: int, *, calibrates: bool = False
) -> tuple[Executor, int]:
    """A local executor sized for `pending` logs, and the chunk jobs each audit gets.

    One worker per core auditing whole logs; only with fewer logs than cores does each
    audit also read its chunks in parallel (cores shared out between the logs). Workers
    that may calibrate start as fresh interpreters (see `LocalExecutor`).
    """
    if options.cluster is not None:
        from syncaudit.fleet.dask_executor import DaskExecutor

        return DaskExecutor(options.cluster, timeout_s=options.timeout_s, task=run_any_log_job), 1
    cores = options.jobs or default_jobs()
    workers = max(1, min(cores, pending))
    audit_jobs = max(1, cores // workers) if pending < cores else 1
    executor = LocalExecutor(
        workers,
        timeout_s=options.timeout_s,
        max_tries=options.max_tries,
        task=run_any_log_job,
        fresh_workers=calibrates,
    )
    return executor, audit_jobs


def run_gate(
    inputs: list[str],
    policy: Policy,
    options: GateOptions,
    *,
    executor: Executor | None = None,
    progress: Progress | None = None,
) -> GateRun:
    """Judge every log named by `inputs` against `policy`; write the outputs and the DB.

    Every output is checked before any work and committed together at the end; a failure
    or an interruption (KeyboardInterrupt, `Interrupted`) leaves no temporary and the
    previous outputs as they were. The database keeps the verdicts reached so far.
    """
    with plan_outputs(inputs, options) as outputs:
        run = _run(inputs, policy, options, outputs, executor, progress)
        outputs.write_summaries(run.logs, policy.fingerprint(), run.warnings)
    return run


@dataclass(frozen=True, slots=True)
class _Pending:
    """A log to audit: its job, its content's and its rig's fingerprints."""

    job: LogJob
    fingerprint: str
    rig_fingerprint: str | None

    def key(self, policy_fp: str) -> str:
        """The database key its verdict will have."""
        return log_key(
            self.fingerprint, _stored(self.job.path), __version__, self.rig_fingerprint, policy_fp
        )


def _run(
    inputs: list[str],
    policy: Policy,
    options: GateOptions,
    outputs: GateOutputs,
    executor: Executor | None,
    progress: Progress | None,
) -> GateRun:
    """Find, fingerprint, skip what the database knows, plan reports, audit the rest."""
    found = discover(inputs, policy)
    policy_fp = policy.fingerprint()
    judged, pending = _fingerprint(found.problems, found.jobs, policy_fp)
    db = ResultsDB(options.db) if options.db is not None else None
    if db is not None and not options.force:
        known, pending = _known(db, pending, policy_fp, options.html_dir is not None)
        judged.extend(known)
    if options.html_dir is not None:  # every report's target checked before the audits
        _plan_reports(outputs, judged, pending, policy_fp)
    total = len(judged) + len(pending)
    for index, log in enumerate(judged, 1):
        if progress:
            progress(log, index, total)
    unsaved: list[JudgedLog] = [log for log in judged if not log.skipped]
    if pending:
        unsaved = _audit(pending, policy, options, outputs, db, executor, progress, judged, unsaved)
    run = GateRun(sorted(judged, key=lambda log: log.path), found.warnings)
    _save_reports(unsaved, outputs)
    if db is not None:
        db.write(unsaved)
    return run


def _fingerprint(
    problems: list[str], jobs: list[LogJob], policy_fp: str
) -> tuple[list[JudgedLog], list[_Pending]]:
    """Error rows for what discovery could not use or read; the rest, fingerprinted."""
    judged: list[JudgedLog] = []
    pending: list[_Pending] = []
    for problem in problems:
        item = problem.split(": ", 1)[0]
        judged.append(_error_log(LogJob(path=item), LogReadError(problem), policy_fp))
    for job in jobs:
        try:
            fp = fingerprint(job.path)
        except SyncauditError as exc:
            judged.append(_error_log(job, exc, policy_fp))
            continue
        except OSError as exc:
            judged.append(
                _error_log(job, LogReadError(f"{job.path}: {exc.strerror or exc}"), policy_fp)
            )
            continue
        pending.append(_Pending(job, fp, file_fingerprint(job.rig_path)))
    return judged, pending


def _known(
    db: ResultsDB, pending: list[_Pending], policy_fp: str, wants_reports: bool
) -> tuple[list[JudgedLog], list[_Pending]]:
    """Verdicts the database holds for unchanged logs (skipped), and the logs still to audit.

    Error rows are judged again: a timeout or a dead worker may not recur. So is a log
    whose report is asked for (--html) but gone (e.g. an interrupted run's).
    """
    keys = {p.key(policy_fp): p.job for p in pending}
    known = {
        k: v
        for k, v in db.known(keys).items()
        if v.verdict != "error"
        and (not wants_reports or (v.report is not None and Path(v.report).is_file()))
    }
    skipped = []
    for key, stored in known.items():
        job = keys[key]
        stored.job = LogJob(job.path, job.vehicle, job.rig_path, job.tags, job.source)
        skipped.append(stored)
    return skipped, [p for p in pending if p.key(policy_fp) not in known]


def _plan_reports(
    outputs: GateOutputs, judged: list[JudgedLog], pending: list[_Pending], policy_fp: str
) -> None:
    """Check every report's target before any audit (exists without --overwrite: exit 8)."""
    for log in judged:
        if not log.skipped:
            outputs.plan_report(report_name(log))
    for p in pending:
        outputs.plan_report(report_file_name(display_path(_shown(p.job.path)), p.key(policy_fp)))


def _audit(
    pending: list[_Pending],
    policy: Policy,
    options: GateOptions,
    outputs: GateOutputs,
    db: ResultsDB | None,
    executor: Executor | None,
    progress: Progress | None,
    judged: list[JudgedLog],
    unsaved: list[JudgedLog],
) -> list[JudgedLog]:
    """Audit the pending logs, judge each as it comes, save to the database in batches.

    Appends every verdict to `judged`; returns the verdicts not saved yet.
    """
    policy_fp = policy.fingerprint()
    total = len(judged) + len(pending)
    by_path = {p.job.path: p for p in pending}
    own = executor is None
    if executor is None:
        executor, audit_jobs = make_executor(options, len(pending), calibrates=policy.calibrates())
    else:
        audit_jobs = 1
    job_options = JobOptions(
        audit_jobs=audit_jobs,
        calibrate=policy.calibrates(),
        html=options.html_dir is not None,
        policy=policy,
    )
    last_save = time.monotonic()
    try:
        for outcome in executor.run([p.job for p in pending], job_options):
            p = by_path[outcome.job.path]
            log = _judge(outcome, policy, p.fingerprint, p.rig_fingerprint, policy_fp)
            if db is None:
                log.audit = None  # only the database needs it: memory flat in the logs
            judged.append(log)
            unsaved.append(log)
            if progress:
                progress(log, len(judged), total)
            if db is not None and (
                len(unsaved) >= DB_BATCH_LOGS or time.monotonic() - last_save > DB_BATCH_S
            ):
                _save_reports(unsaved, outputs)
                db.write(unsaved)
                for saved in unsaved:
                    saved.audit = None  # in the database now: memory flat in the logs
                unsaved, last_save = [], time.monotonic()
    finally:
        if own:
            executor.close()
    return unsaved


def _shown(path: str) -> str:
    """A log's path as its verdict shows it (URLs without query string)."""
    return public_url(path) if is_url(path) else path


def _save_reports(logs: list[JudgedLog], outputs: GateOutputs) -> None:
    """Write each new log's HTML report (before its row, which records the report path)."""
    if outputs.html_dir is None:
        for log in logs:
            log.html = None
        return
    for log in logs:
        if log.skipped:
            continue
        outputs.write_report(log, report_name(log), log.html or render_error_page(log))
        log.html = None  # keep memory flat in the number of logs
