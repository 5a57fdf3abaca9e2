"""`gate --init`: a policy written from known-good logs, with documented margins.

Each limit is what the good logs showed, widened by a margin so that ordinary
log-to-log variation passes while a real regression fails:

- upper limits on times (Eq. 5 mean, p99, max, t1..t4 p99, |recommended - applied|):
  1.5 x the worst good value + 50 us (jitter of tens of us must not flip a verdict);
- Eq. 6 variance: 2.25 x the worst good value + 2500 us^2 (the square of the above);
- paired fraction: 0.9 x the lowest good value; LiDAR drop rate: 2 x the worst, at
  least 0.001; RPM and packets per revolution: the good range widened by 2 %;
- duration: at least half the shortest good log; required topics: those every good log
  has; LiDAR clock: as every good log showed it (warn only).
Eq. 5, Eq. 6, paired fraction and required topics `fail`; the others `warn`, to be
tightened by hand once the fleet's spread is known. `defaults` hold the loosest limit
over all cameras, `cameras.<name>` each camera's own.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any

from syncaudit.fleet.checks import _camera_values, drop_rate
from syncaudit.fleet.job import LogOutcome
from syncaudit.fleet.policy import Policy, parse_policy, policy_to_yaml

TIME_FACTOR, TIME_SLACK_US = 1.5, 50.0
VAR_FACTOR, VAR_SLACK_US2 = 2.25, 2500.0
FAIL_CHECKS = {"error_mean_us", "error_var_us2", "paired_fraction"}


def _upper(name: str, worst: float) -> float:
    if name == "error_var_us2":
        return round(worst * VAR_FACTOR + VAR_SLACK_US2, 1)
    return round(worst * TIME_FACTOR + TIME_SLACK_US, 1)


def _camera_limits(values: dict[str, list[float]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, seen in values.items():
        if not seen:
            continue
        severity = "fail" if name in FAIL_CHECKS else "warn"
        if name == "paired_fraction":
            out[name] = {"min": round(min(seen) * 0.9, 4), "severity": severity}
        else:
            out[name] = {"max": _upper(name, max(seen)), "severity": severity}
    return out


def policy_from_outcomes(outcomes: list[LogOutcome]) -> Policy:
    """A policy every one of these (audited) logs passes, with the margins above."""
    good = [o for o in outcomes if o.ok and o.audit is not None]
    if not good:
        raise ValueError("no log could be audited")
    per_camera: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    every: dict[str, list[float]] = defaultdict(list)
    lidar: dict[str, list[float]] = defaultdict(list)
    synced: set[bool | None] = set()
    for outcome in good:
        audit = outcome.audit or {}
        for cam in audit.get("cameras", []):
            for name, value in _camera_values(cam).items():
                if value is not None:
                    per_camera[cam["camera"]][name].append(value)
                    every[name].append(value)
        row = audit.get("lidar") or {}
        for name, value in (
            ("drop_rate", drop_rate(row)),
            ("rpm", row.get("rpm")),
            ("packets_per_revolution", row.get("packets_per_revolution")),
            ("duration_s", audit.get("duration_s")),
        ):
            if value is not None:
                lidar[name].append(float(value))
        synced.add(row.get("clock_synchronised"))
    topics = set.intersection(*(set(o.topics) for o in good))
    lidar_checks: dict[str, Any] = {}
    if lidar["drop_rate"]:
        lidar_checks["drop_rate"] = {
            "max": round(max(max(lidar["drop_rate"]) * 2, 0.001), 5),
            "severity": "warn",
        }
    for name in ("rpm", "packets_per_revolution"):
        if lidar[name]:
            lo, hi = min(lidar[name]), max(lidar[name])
            lidar_checks[name] = {
                "min": round(lo * 0.98, 2),
                "max": round(hi * 1.02, 2),
                "severity": "warn",
            }
    if len(synced) == 1 and None not in synced:
        lidar_checks["clock_synchronised"] = {"expect": synced.pop(), "severity": "warn"}
    else:
        lidar_checks["clock_synchronised"] = None
    log_checks: dict[str, Any] = {"required_topics": {"topics": sorted(topics), "severity": "fail"}}
    if lidar["duration_s"]:
        log_checks["duration_s"] = {
            "min": round(min(lidar["duration_s"]) * 0.5, 3),
            "severity": "warn",
        }
    camera_defaults = _camera_limits(every)
    for name in ("error_mean_us", "error_var_us2", "paired_fraction"):
        camera_defaults.setdefault(name, None)  # never measured in the good logs: off
    raw = {
        "version": 1,
        "description": f"written by syncaudit gate --init from {len(good)} known-good log(s)",
        "defaults": {"camera": camera_defaults, "lidar": lidar_checks, "log": log_checks},
        "cameras": {name: _camera_limits(values) for name, values in sorted(per_camera.items())},
    }
    return parse_policy(raw, "gate --init")


INIT_HEADER = """\
# syncaudit gate policy, written by `syncaudit gate --init` from known-good logs.
# Margins (docs/fleet.md): time limits 1.5 x the worst good value + 50 us; Eq. 6 variance
# 2.25 x + 2500 us^2; paired fraction 0.9 x the lowest; drop rate 2 x the worst (>= 0.001);
# RPM and packets/rev the good range +-2 %; duration >= half the shortest; required topics
# those every good log had. Eq. 5/6, paired fraction, topics: fail; the rest: warn.
# Override per vehicle under `vehicles.<id>` and per camera under `cameras.<name>`.
"""


def init_policy_yaml(outcomes: list[LogOutcome]) -> str:
    """The policy file text for `gate --init`."""
    return policy_to_yaml(policy_from_outcomes(outcomes), INIT_HEADER)
