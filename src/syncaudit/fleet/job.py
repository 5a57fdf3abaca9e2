"""What a worker does with one log: audit it (and calibrate it when it holds the scans).

`run_log_job` never raises for a problem of the log: it returns a `LogOutcome` with the
error, so the driver records an error row. Everything in the outcome is plain data
(picklable, JSON-ready) so it can come back from a process or a remote worker.
"""

from __future__ import annotations

import os
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from syncaudit.errors import SyncauditError
from syncaudit.fleet.inputs import LogJob
from syncaudit.fleet.policy import Policy

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"


@dataclass(frozen=True, slots=True)
class JobOptions:
    """How a worker treats each log."""

    audit_jobs: int = 1
    """Chunk worker processes inside one log (1 when logs run in parallel)."""
    calibrate: bool = False
    """Run the extrinsic calibration where the log has two or more point-cloud topics."""
    html: bool = False
    """Render the per-log HTML report (returned as text; the driver writes it)."""
    policy: Policy | None = None
    """The policy, for the checks section of the HTML report."""


@dataclass(slots=True)
class LogOutcome:
    """The result of one log: an audit (as `AuditResult.to_dict()`) or an error."""

    job: LogJob
    audit: dict[str, Any] | None = None
    topics: list[str] = field(default_factory=list)
    start_ns: int | None = None
    calibration: list[dict[str, Any]] | None = None
    """One entry per calibrated extrinsic (topic, rotation_diff_deg, translation_diff_cm)."""
    calibration_error: str | None = None
    html: str | None = None
    error: str | None = None
    error_code: int | None = None
    attempts: int = 1
    elapsed_s: float = 0.0
    remote_read: dict[str, Any] | None = None
    """For a URL: bytes fetched against the file size (`remote.fetch.FetchStats`)."""

    @property
    def ok(self) -> bool:
        """The audit ran."""
        return self.audit is not None and self.error is None


def run_log_job(job: LogJob, options: JobOptions) -> LogOutcome:
    """Audit one log; any failure becomes the outcome's error (never an exception)."""
    started = time.perf_counter()
    outcome = LogOutcome(job=job)
    try:
        _audit_into(outcome, job, options)
    except SyncauditError as exc:
        outcome.error, outcome.error_code = str(exc).splitlines()[0], exc.exit_code
    except MemoryError:
        outcome.error, outcome.error_code = "out of memory while auditing", 3
    except Exception as exc:  # a bug on this log's data: recorded, the run goes on
        where = traceback.extract_tb(exc.__traceback__)[-1]
        outcome.error = (
            f"internal error: {type(exc).__name__}: {exc} "
            f"(at {Path(where.filename).name}:{where.lineno})"
        )
        outcome.error_code = 70
    outcome.elapsed_s = time.perf_counter() - started
    return outcome


def _audit_into(outcome: LogOutcome, job: LogJob, options: JobOptions) -> None:
    from syncaudit.audit import audit_log
    from syncaudit.logs import open_log
    from syncaudit.rig import load_rig

    rig = load_rig(job.rig_path) if job.rig_path else None
    with open_log(job.path) as log:
        outcome.topics = sorted(log.topics)
        outcome.start_ns = log.summary.start_ns
        clouds = [t.name for t in log.topics.values() if t.msgtype == POINTCLOUD2]
    result = audit_log(job.path, rig, jobs=options.audit_jobs)
    outcome.audit = result.to_dict()
    if options.calibrate and len(clouds) >= 2:
        _calibrate_into(outcome, job)
    if options.html:
        from syncaudit.fleet.checks import evaluate
        from syncaudit.fleet.html import checks_section
        from syncaudit.report.html import render_audit_html

        checks = evaluate(outcome, options.policy, job.vehicle) if options.policy else []
        outcome.html = render_audit_html(result, [checks_section(checks)])


def _calibrate_into(outcome: LogOutcome, job: LogJob) -> None:
    """Calibrate with the default configuration; a failure is kept, not raised."""
    try:
        from syncaudit.calib.config import CalibConfig
        from syncaudit.calib.pipeline import calibrate_log

        result = calibrate_log(Path(job.path), CalibConfig())
        outcome.calibration = [
            {
                "topic": ext.topic,
                "reference_topic": ext.reference_topic,
                "rotation_diff_deg": ext.rotation_diff_deg,
                "translation_diff_cm": ext.translation_diff_cm,
                "calibrated": ext.calibrated,
                "reason": ext.reason,
            }
            for ext in result.extrinsics
        ]
    except SyncauditError as exc:
        outcome.calibration_error = str(exc).splitlines()[0]
    except Exception as exc:
        outcome.calibration_error = f"internal error: {type(exc).__name__}: {exc}"


def apply_test_hooks(path: str) -> None:
    """Test hooks, read in the worker: make it die or hang on logs whose path contains a marker.

    SYNCAUDIT_FLEET_TEST_CRASH=<substring> exits the worker process at once (as a
    segfault or the OOM killer would); SYNCAUDIT_FLEET_TEST_HANG=<substring> sleeps past
    any timeout. They let the tests (and anyone checking a deployment) see that a dead
    worker costs a retry and then an error row, and a hung log a timeout row, never the run.
    """
    crash = os.environ.get("SYNCAUDIT_FLEET_TEST_CRASH")
    if crash and crash in path:
        os._exit(86)
    hang = os.environ.get("SYNCAUDIT_FLEET_TEST_HANG")
    if hang and hang in path:
        time.sleep(3600)
