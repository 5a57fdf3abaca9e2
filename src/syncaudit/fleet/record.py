"""`JudgedLog`: one log's verdict with everything the outputs and the database need."""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, field
from typing import Any

from syncaudit.fleet.checks import CheckResult
from syncaudit.fleet.inputs import LogJob


def log_key(
    fingerprint: str, path: str, tool_version: str, rig_fp: str | None, policy_fp: str
) -> str:
    """The database key of a verdict: same content at the same place, tool, rig and policy
    = same key (skipped). The path is part of it: two copies of one log are two rows."""
    where = display_path(path) if "://" in path else os.path.abspath(path)
    text = "|".join((fingerprint, where, tool_version, rig_fp or "-", policy_fp))
    return hashlib.sha256(text.encode()).hexdigest()[:24]


def display_path(path: str) -> str:
    """A path or URL as stored: URLs lose their query string and fragment (credentials)."""
    if "://" in path:
        return path.split("?", 1)[0].split("#", 1)[0]
    return path


@dataclass(slots=True)
class JudgedLog:
    """A log's verdict, its checks and the audit it came from (None for error rows)."""

    job: LogJob
    key: str
    fingerprint: str
    rig_fingerprint: str | None
    policy_fingerprint: str
    tool_version: str
    verdict: str
    checks: list[CheckResult] = field(default_factory=list)
    audit: dict[str, Any] | None = None
    start_ns: int | None = None
    error: str | None = None
    error_code: int | None = None
    attempts: int = 1
    elapsed_s: float = 0.0
    skipped: bool = False
    """Unchanged since an earlier run with the same tool, rig and policy: read from the DB."""
    report: str | None = None
    html: str | None = None
    camera_count: int | None = None
    """Cameras the audit judged (None for error rows and rows read from the database)."""
    remote_read: dict[str, Any] | None = None
    """For a URL: what the ranged reads fetched (bytes, requests, chunks)."""
    duration_s: float | None = None
    container: str | None = None
    """From the log's index (also for a calibration session, which has no audit)."""
    health: dict[str, Any] | None = None
    """The file's condition (the audit's `health`: cut off, damaged messages, no index)."""
    advice: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Per camera, the audit's `recommendation` (absent from audits that have none)."""

    @property
    def why_failed(self) -> str:
        """Why a failing log failed when none of its `fail` checks did ('' otherwise)."""
        if self.verdict != "fail" or any(c.severity == "fail" for c in self.failed_checks):
            return ""
        if self.camera_count == 0 or (self.audit is not None and not self.audit.get("cameras")):
            return "no camera to judge in this log (a LiDAR-only log cannot pass the sync gate)"
        if not any(c.scope == "calibration" for c in self.checks) and self.camera_count is None:
            return "nothing judged it: no camera audited and no calibration check ran"
        return "no check judged it"

    @property
    def path(self) -> str:
        """Where the log is, as stored and shown."""
        return display_path(self.job.path)

    @property
    def failed_checks(self) -> list[CheckResult]:
        """Checks that did not pass, fail severity first."""
        bad = [c for c in self.checks if not c.passed]
        return sorted(bad, key=lambda c: (c.severity != "fail", c.scope, c.subject, c.check))
