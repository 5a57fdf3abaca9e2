"""The gate's task for a log that may be a URL: read by ranges where it can be, else fetched.

An MCAP file, a ROS 1 bag or a ROS 2 bag prefix with MCAP storage is opened by
`logs.open_log(URL)` (its index fetched by the parent, its chunk runs by each chunk worker
into memory): nothing is written to disk. Other logs are copied to
$SYNCAUDIT_REMOTE_TMPDIR (e.g. /dev/shm when memory allows), else the system temp
folder, and the copy is removed when the audit ends. Runs in the
gate's worker (a local process or a cluster worker), so the bytes travel from the object
store to where the audit runs, never through the driver.
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import replace
from pathlib import Path

from syncaudit.errors import SyncauditError
from syncaudit.fleet.inputs import LogJob
from syncaudit.fleet.job import JobOptions, LogOutcome, run_log_job
from syncaudit.logs import open_log
from syncaudit.remote.fetch import fetch_log
from syncaudit.remote.file import RemoteUnindexedError
from syncaudit.remote.urls import is_url


def rig_topics(rig_path: str | None) -> frozenset[str] | None:
    """Every topic a rig names (LiDAR, its metadata, each camera's) and /tf_static, /tf
    (camera yaws); None without a rig (then every chunk is fetched)."""
    if rig_path is None:
        return None
    from syncaudit.audit.rig_beside import load_rig_at

    rig = load_rig_at(rig_path)
    topics: set[str] = {"/tf_static", "/tf"}
    for part in (rig.lidar, *rig.cameras):
        for name in type(part).model_fields:
            value = getattr(part, name)
            if name.endswith("topic") and isinstance(value, str):
                topics.add(value)
    return frozenset(topics)


def run_any_log_job(job: LogJob, options: JobOptions) -> LogOutcome:
    """`run_log_job` for local paths and for URLs read by ranges (MCAP files, ROS 1 bags,
    ROS 2 bag prefixes with MCAP storage: straight into each chunk worker's memory); the
    rest (SQLite storage, a log without index, a log to calibrate) is fetched into a
    temporary folder first, `remote_read.whole_reason` saying why."""
    if not is_url(job.path):
        return run_log_job(job, options)
    reason = "--calibrate reads point clouds through a local path"
    if not options.calibrate:
        try:
            log = open_log(job.path)
        except RemoteUnindexedError as exc:  # not readable by ranges: read from a copy below
            reason = exc.whole_reason
        except SyncauditError:
            return run_log_job(job, options)  # the job's own outcome of that error
        else:
            with log:  # open across the job's own opens: they reuse what it fetched
                outcome = run_log_job(job, options)
                stats = log.fetch_stats
            outcome.remote_read = stats.to_dict() if stats is not None else None
            return outcome
    try:
        topics = None if options.calibrate else rig_topics(job.rig_path)
    except SyncauditError as exc:
        return LogOutcome(job=job, error=str(exc).splitlines()[0], error_code=exc.exit_code)
    outcome = _fetch_and_audit(job, options, topics)
    if topics is not None and outcome.remote_read is not None and outcome.error_code in (3, 7):
        # The rig's topics missed something the audit reads (a chunk hole): every chunk.
        outcome = _fetch_and_audit(job, options, None)
    if outcome.remote_read is not None:
        outcome.remote_read["whole_reason"] = reason  # why it was downloaded, said once
    return outcome


def _fetch_and_audit(job: LogJob, options: JobOptions, topics: frozenset[str] | None) -> LogOutcome:
    scratch = os.environ.get("SYNCAUDIT_REMOTE_TMPDIR") or None
    with tempfile.TemporaryDirectory(prefix="syncaudit-remote-", dir=scratch) as folder:
        try:
            local, stats = fetch_log(job.path, Path(folder), topics=topics)
        except SyncauditError as exc:
            return LogOutcome(job=job, error=str(exc).splitlines()[0], error_code=exc.exit_code)
        outcome = run_log_job(replace(job, path=str(local)), options)
        outcome.job = job
        outcome.remote_read = stats.to_dict()
        if outcome.error:
            outcome.error = outcome.error.replace(str(local), stats.url)
        return outcome
