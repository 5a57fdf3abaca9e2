"""What a worker does with one log: audit it (and calibrate it when it holds the scans).

A log with LiDAR packets gets the sync audit; a log with two or more PointCloud2 topics
is also calibrated when the policy switches a calibration check on for its vehicle; a log
with point clouds but no LiDAR packets (a calibration session) is calibrated only, and
judged on its calibration and log checks.

`run_log_job` never raises for a problem of the log: it returns a `LogOutcome` with the
error, so the driver records an error row. Everything in the outcome is plain data
(picklable, JSON-ready) so it can come back from a process or a remote worker.
"""

from __future__ import annotations

import html
import os
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from syncaudit.errors import NoDataError, SyncauditError
from syncaudit.fleet.inputs import LogJob
from syncaudit.fleet.policy import Policy

if TYPE_CHECKING:
    from syncaudit.calib.result import CalibrationResult

POINTCLOUD2_TYPES = frozenset({"sensor_msgs/msg/PointCloud2", "sensor_msgs/PointCloud2"})
"""PointCloud2 as ROS 2 (MCAP, .db3) and ROS 1 bags name it."""


@dataclass(frozen=True, slots=True)
class JobOptions:
    """How a worker treats each log."""

    audit_jobs: int = 1
    """Chunk worker processes inside one log (1 when logs run in parallel)."""
    calibrate: bool = False
    """Run the extrinsic calibration where the log has two or more point-cloud topics (and
    `policy`, when given, has a calibration check on for the log's vehicle)."""
    html: bool = False
    """Render the per-log HTML report's sections (returned as text; the driver, which judges
    the log, adds its policy checks and writes the page)."""
    policy: Policy | None = None
    """The policy, for which vehicles' logs are worth calibrating."""


@dataclass(frozen=True, slots=True)
class ReportDraft:
    """A log's report page without its policy checks (`fleet.log_pages.render_log_page`)."""

    title: str
    body: str
    """The audit's and/or the calibration's sections (HTML)."""
    t0_ns: float | None = None
    """The audit's time origin (wall-clock labels of the time plots); None without audit."""


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
    calibration_only: bool = False
    """Point clouds but no LiDAR packets: calibrated, not sync-audited (`audit` is None)."""
    duration_s: float | None = None
    container: str | None = None
    report_draft: ReportDraft | None = None
    error: str | None = None
    error_code: int | None = None
    attempts: int = 1
    elapsed_s: float = 0.0
    remote_read: dict[str, Any] | None = None
    """For a URL: bytes fetched against the file size (`remote.fetch.FetchStats`)."""

    @property
    def ok(self) -> bool:
        """The log was judged: its audit ran, or it is a calibration session that was read."""
        return self.error is None and (self.audit is not None or self.calibration_only)


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


def wants_calibration(options: JobOptions, job: LogJob) -> bool:
    """Whether this log's policy checks its extrinsics (so its scans are worth calibrating)."""
    if not options.calibrate:
        return False
    return options.policy is None or options.policy.checks_for(job.vehicle).calibration.enabled


def _audit_into(outcome: LogOutcome, job: LogJob, options: JobOptions) -> None:
    from syncaudit.audit.probe import lidar_family
    from syncaudit.audit.rig_beside import load_rig_at
    from syncaudit.audit.run import audit_log
    from syncaudit.logs import open_log

    rig = load_rig_at(job.rig_path) if job.rig_path else None
    with open_log(job.path) as log:
        outcome.topics = sorted(log.topics)
        outcome.start_ns = log.summary.start_ns
        outcome.duration_s = log.summary.duration_s
        outcome.container = log.summary.container
        clouds = sorted(t.name for t in log.topics.values() if t.msgtype in POINTCLOUD2_TYPES)
        has_packets = any(lidar_family(t.msgtype) for t in log.topics.values())
    calibrate = len(clouds) >= 2 and wants_calibration(options, job)
    result = None
    if has_packets or len(clouds) < 2:
        result = audit_log(job.path, rig, jobs=options.audit_jobs)
        outcome.audit = result.to_dict()
    elif calibrate:
        outcome.calibration_only = True
    else:
        raise NoDataError(
            f"{job.path}: holds {len(clouds)} PointCloud2 topics but no LiDAR packets (a "
            "calibration session?): only calibration checks can judge it, and the policy "
            "switches none on for this log (calibration: rotation_deg / translation_cm)"
        )
    calibration = _calibrate_into(outcome, job) if calibrate else None
    if options.html:
        outcome.report_draft = _report_draft(outcome, job, result, calibration)


def _report_draft(
    outcome: LogOutcome, job: LogJob, result: Any, calibration: CalibrationResult | None
) -> ReportDraft:
    """The log's report page but its policy checks: its audit and/or calibration."""
    from syncaudit.report.html import audit_sections, time_origin_ns

    parts = [] if result is None else [audit_sections(result, under_gate=True)]
    if calibration is not None:
        from syncaudit.report.calib_section import html_section

        parts.append(html_section(calibration))
    elif outcome.calibration_error is not None:
        parts.append(f"<h2>Calibration</h2><p>{html.escape(outcome.calibration_error)}</p>")
    t0 = time_origin_ns(result) if result is not None else None
    return ReportDraft(f"syncaudit: {job.path}", "".join(parts), t0)


def _calibrate_into(outcome: LogOutcome, job: LogJob) -> CalibrationResult | None:
    """Calibrate with the default configuration; a failure is kept, not raised."""
    try:
        from syncaudit.calib.pipeline import calibrate_log
        from syncaudit.calib.settings import CalibConfig

        result = calibrate_log(Path(job.path), CalibConfig())
    except SyncauditError as exc:
        outcome.calibration_error = str(exc).splitlines()[0]
        return None
    except ImportError as exc:
        outcome.calibration_error = (
            f"the calibration needs syncaudit[calib] on the worker ({exc.name} is missing)"
        )
        return None
    except Exception as exc:
        outcome.calibration_error = f"internal error: {type(exc).__name__}: {exc}"
        return None
    outcome.calibration = [
        {
            "topic": ext.topic,
            "reference_topic": ext.reference_topic,
            "rotation_diff_deg": ext.rotation_diff_deg,
            "translation_diff_cm": ext.translation_diff_cm,
            "calibrated": ext.calibrated,
            "reason": ext.reason or (None if ext.calibrated else result.reason),
        }
        for ext in result.extrinsics
    ]
    return result


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
