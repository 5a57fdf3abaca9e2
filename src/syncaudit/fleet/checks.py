"""Judging one log's audit against the policy: one `CheckResult` per check and subject."""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any

from syncaudit.fleet.job import LogOutcome
from syncaudit.fleet.policy import CheckSet, Condition, Flag, Limit, Policy, TopicsCheck

UNITS: dict[str, str] = {
    "error_mean_us": "us",
    "error_var_us2": "us^2",
    "error_p99_us": "us",
    "error_max_us": "us",
    "paired_fraction": "",
    "delay_mismatch_us": "us",
    "t1_p99_us": "us",
    "t2_p99_us": "us",
    "t3_p99_us": "us",
    "t4_p99_us": "us",
    "clock_synchronised": "",
    "drop_rate": "",
    "rpm": "rpm",
    "packets_per_revolution": "packets",
    "required_topics": "topics missing",
    "duration_s": "s",
    "damaged_messages": "messages",
    "rotation_deg": "deg",
    "translation_cm": "cm",
}


@dataclass(frozen=True, slots=True)
class CheckResult:
    """One check of one subject (a camera, the LiDAR, the log, an extrinsic)."""

    scope: str
    """'camera', 'lidar', 'log' or 'calibration'."""
    subject: str
    """Camera name, LiDAR topic, 'log', or the calibrated LiDAR topic."""
    check: str
    value: float | None
    """The measured value; None when it could not be measured (the check then fails)."""
    limit: str
    """The limit as written: `<= 250`, `>= 0.5`, `590..610`, `== true`, `all present`."""
    unit: str
    severity: str
    passed: bool
    message: str
    limit_min: float | None = None
    limit_max: float | None = None
    """The numeric bounds of `limit` (None where open), for plots and SQL."""

    def to_dict(self) -> dict[str, Any]:
        """JSON form."""
        return asdict(self)


def _fmt(value: float) -> str:
    return f"{value:.6g}"


def is_boolean(check: CheckResult) -> bool:
    """A yes/no check (a flag or a condition of the file): its value is 0 or 1."""
    return check.limit in ("== true", "== false")


def shown_value(check: CheckResult) -> str:
    """The measured value as a summary shows it: `true`/`false` for yes/no checks, the
    missing topics for `required_topics`, else the number with its unit."""
    if check.value is None:
        return "not measured"
    if is_boolean(check):
        return str(bool(check.value)).lower()
    if check.check == "required_topics" and not check.passed:
        return check.message
    return f"{_fmt(check.value)} {check.unit}".strip()


def shown_limit(check: CheckResult) -> str:
    """The limit with its unit (`<= 250 us`, `== false`, `== 0 topics missing`)."""
    return f"{check.limit} {check.unit}".strip() if not is_boolean(check) else check.limit


def _limit_text(limit: Limit) -> str:
    if limit.min is not None and limit.max is not None:
        return f"{_fmt(limit.min)}..{_fmt(limit.max)}"
    if limit.max is not None:
        return f"<= {_fmt(limit.max)}"
    if limit.min is not None:
        return f">= {_fmt(limit.min)}"
    return "any"


def judge_limit(
    scope: str, subject: str, check: str, limit: Limit, value: float | None, why_missing: str = ""
) -> CheckResult:
    """Compare a measured value with a [min, max] limit."""
    unit = UNITS.get(check, "")
    text = _limit_text(limit)
    if value is None:
        reason = why_missing or "not measured in this log"
        return CheckResult(
            scope,
            subject,
            check,
            None,
            text,
            unit,
            limit.severity,
            False,
            reason,
            limit.min,
            limit.max,
        )
    passed = (limit.min is None or value >= limit.min) and (limit.max is None or value <= limit.max)
    unit_text = f" {unit}" if unit else ""
    message = f"{check} = {_fmt(value)}{unit_text} (limit {text}{unit_text})"
    return CheckResult(
        scope,
        subject,
        check,
        value,
        text,
        unit,
        limit.severity,
        passed,
        message,
        limit.min,
        limit.max,
    )


def _judge_flag(
    scope: str, subject: str, check: str, flag: Flag, value: bool | None
) -> CheckResult:
    text = f"== {str(flag.expect).lower()}"
    if value is None:
        return CheckResult(
            scope, subject, check, None, text, "", flag.severity, False, "not measured"
        )
    message = f"{check} = {str(value).lower()} (expected {str(flag.expect).lower()})"
    return CheckResult(
        scope, subject, check, float(value), text, "", flag.severity, value == flag.expect, message
    )


def _camera_values(cam: dict[str, Any]) -> dict[str, float | None]:
    total = cam.get("frames_total") or 0
    applied, recommended = cam.get("delay_applied_us"), cam.get("delay_recommended_us")
    values: dict[str, float | None] = {
        "error_mean_us": cam.get("error_mean_us"),
        "error_var_us2": cam.get("error_var_us2"),
        "error_p99_us": cam.get("error_p99_us"),
        "error_max_us": cam.get("error_max_us"),
        "paired_fraction": (cam.get("frames_paired") or 0) / total if total else None,
        "delay_mismatch_us": abs(recommended - applied)
        if applied is not None and recommended is not None
        else None,
    }
    for name in ("t1", "t2", "t3", "t4"):
        values[f"{name}_p99_us"] = (cam.get("latencies") or {}).get(name, {}).get("p99_us")
    return values


def drop_rate(lidar: dict[str, Any]) -> float | None:
    """Dropped over expected packets (received + dropped)."""
    packets, dropped = lidar.get("packets") or 0, lidar.get("dropped_packets") or 0
    return dropped / (packets + dropped) if packets + dropped else None


def evaluate(outcome: LogOutcome, policy: Policy, vehicle: str | None) -> list[CheckResult]:
    """Every enabled check of the policy on one judged log (empty for an error outcome).

    A calibration session (point clouds, no LiDAR packets) has no sync audit: its log and
    calibration checks apply, the camera and LiDAR checks have nothing to judge.
    """
    if not outcome.ok:
        return []
    audit = outcome.audit
    results: list[CheckResult] = []
    base = policy.checks_for(vehicle)
    results.extend(_log_checks(base, outcome, audit or {}))
    if audit is not None:
        results.extend(_lidar_checks(base, audit))
    for cam in (audit or {}).get("cameras", []):
        checks = policy.checks_for(vehicle, cam["camera"]).camera
        values = _camera_values(cam)
        for name in type(checks).model_fields:
            limit = getattr(checks, name)
            if limit is None or not limit.enabled:
                continue
            results.append(judge_limit("camera", cam["camera"], name, limit, values[name]))
    results.extend(_calibration_checks(base, outcome))
    return sorted(results, key=lambda r: (r.scope, r.subject, r.check))


def _log_checks(base: CheckSet, outcome: LogOutcome, audit: dict[str, Any]) -> list[CheckResult]:
    out = []
    topics: TopicsCheck | None = base.log.required_topics
    if topics is not None and topics.enabled:
        missing = sorted(set(topics.topics) - set(outcome.topics))
        message = "all present" if not missing else "missing: " + ", ".join(missing)
        out.append(
            CheckResult(
                "log",
                "log",
                "required_topics",
                float(len(missing)),
                "== 0",
                UNITS["required_topics"],
                topics.severity,
                not missing,
                message,
            )
        )
    if base.log.duration_s is not None and base.log.duration_s.enabled:
        duration = audit.get("duration_s", outcome.duration_s)
        out.append(judge_limit("log", "log", "duration_s", base.log.duration_s, duration))
    health = audit.get("health")
    if isinstance(health, dict):
        out.extend(_health_checks(base, health))
    return out


def _condition(
    check: str, condition: Condition | None, present: bool, why: str
) -> list[CheckResult]:
    """A condition that must be absent: passes when not `present`; `why` says what was found."""
    if condition is None or not condition.enabled:
        return []
    message = f"{check} = {str(present).lower()}" + (f": {why}" if present else "")
    value = float(present)
    return [
        CheckResult(
            "log", "log", check, value, "== false", "", condition.severity, not present, message
        )
    ]


def _health_checks(base: CheckSet, health: dict[str, Any]) -> list[CheckResult]:
    """The file's condition (audit `health`) against the policy's log checks."""
    checks = base.log
    notes = "; ".join(health.get("notes") or [])
    cut = bool(health.get("truncated")) or bool(health.get("cut_chunks"))
    cut_why = "; ".join(p for p in health.get("problems") or [] if "cut" in p)
    out = _condition("truncated", checks.truncated, cut, cut_why or notes)
    out += _condition(
        "missing_index", checks.missing_index, bool(health.get("missing_index")), notes
    )
    limit = checks.damaged_messages
    if limit is not None and limit.enabled:
        damaged: dict[str, int] = health.get("damaged_messages") or {}
        result = judge_limit("log", "log", "damaged_messages", limit, float(sum(damaged.values())))
        if damaged:
            per_topic = ", ".join(f"{topic}: {n}" for topic, n in sorted(damaged.items()))
            result = replace(result, message=f"{result.message}: {per_topic}")
        out.append(result)
    return out


def _lidar_checks(base: CheckSet, audit: dict[str, Any]) -> list[CheckResult]:
    lidar = audit.get("lidar") or {}
    topic = str(lidar.get("topic", "lidar"))
    checks = base.lidar
    out = []
    if checks.clock_synchronised is not None and checks.clock_synchronised.enabled:
        out.append(
            _judge_flag(
                "lidar",
                topic,
                "clock_synchronised",
                checks.clock_synchronised,
                lidar.get("clock_synchronised"),
            )
        )
    values = {
        "drop_rate": drop_rate(lidar),
        "rpm": lidar.get("rpm"),
        "packets_per_revolution": lidar.get("packets_per_revolution"),
    }
    for name, value in values.items():
        limit = getattr(checks, name)
        if limit is not None and limit.enabled:
            out.append(judge_limit("lidar", topic, name, limit, value))
    return out


def _calibration_checks(base: CheckSet, outcome: LogOutcome) -> list[CheckResult]:
    checks = base.calibration
    wanted = [
        (name, getattr(checks, name))
        for name in ("rotation_deg", "translation_cm")
        if getattr(checks, name) is not None and getattr(checks, name).enabled
    ]
    if not wanted:
        return []
    if outcome.calibration is None:
        if outcome.calibration_error is None:
            return []  # the log holds no scans to calibrate with: nothing to judge
        return [
            judge_limit("calibration", "extrinsics", name, limit, None, outcome.calibration_error)
            for name, limit in wanted
        ]
    if not outcome.calibration:
        return [
            judge_limit("calibration", "extrinsics", name, limit, None, "no extrinsic calibrated")
            for name, limit in wanted
        ]
    out = []
    for ext in outcome.calibration:
        values = {
            "rotation_deg": ext["rotation_diff_deg"],
            "translation_cm": ext["translation_diff_cm"],
        }
        why = ext.get("reason") or "not calibrated"
        for name, limit in wanted:
            out.append(judge_limit("calibration", ext["topic"], name, limit, values[name], why))
    return out


def verdict(outcome: LogOutcome, results: list[CheckResult]) -> str:
    """'error' (not audited), 'fail' (a fail check failed, or no camera to judge), 'warn'
    (only warn checks failed) or 'pass'.

    A calibration session has no camera to judge by design: its calibration checks decide.
    """
    if not outcome.ok:
        return "error"
    if not outcome.calibration_only and not (outcome.audit or {}).get("cameras"):
        return "fail"
    if outcome.calibration_only and not any(r.scope == "calibration" for r in results):
        return "fail"  # nothing judged it: never a pass by default
    failed = [r for r in results if not r.passed]
    if any(r.severity == "fail" for r in failed):
        return "fail"
    return "warn" if failed else "pass"
