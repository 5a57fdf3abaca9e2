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
from pathlib import Path
from typing import Any

from syncaudit.fleet.checks import UNITS, _camera_values, drop_rate
from syncaudit.fleet.job import LogOutcome
from syncaudit.fleet.policy import Policy, parse_policy, policy_to_yaml

TIME_FACTOR, TIME_SLACK_US = 1.5, 50.0
VAR_FACTOR, VAR_SLACK_US2 = 2.25, 2500.0
FAIL_CHECKS = {"error_mean_us", "error_var_us2", "paired_fraction"}


Seen = list[tuple[float, str]]
"""Values the good logs showed, each with where it came from ('front in a.mcap')."""


def _upper(name: str, worst: float) -> float:
    if name == "error_var_us2":
        return round(worst * VAR_FACTOR + VAR_SLACK_US2, 1)
    return round(worst * TIME_FACTOR + TIME_SLACK_US, 1)


def _rule(name: str, worst: float, unit: str) -> str:
    if name == "error_var_us2":
        return f"{VAR_FACTOR:g} x {worst:.6g} {unit} + {VAR_SLACK_US2:g}"
    return f"{TIME_FACTOR:g} x {worst:.6g} {unit} + {TIME_SLACK_US:g}"


def _camera_limits(values: dict[str, Seen], where: str, learned: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, seen in values.items():
        if not seen:
            continue
        severity = "fail" if name in FAIL_CHECKS else "warn"
        unit = UNITS.get(name, "")
        if name == "paired_fraction":
            low, source = min(seen)
            out[name] = {"min": round(low * 0.9, 4), "severity": severity}
            learned.append(
                f"{where}.{name}: min {out[name]['min']:g} (0.9 x the lowest, {low:.4g}, "
                f"{source}) {severity}"
            )
        else:
            worst, source = max(seen)
            out[name] = {"max": _upper(name, worst), "severity": severity}
            learned.append(
                f"{where}.{name}: max {out[name]['max']:g} {unit} ({_rule(name, worst, unit)}; "
                f"worst: {source}) {severity}"
            )
    return out


def _name(outcome: LogOutcome) -> str:
    return Path(outcome.job.path).name


def policy_from_outcomes(outcomes: list[LogOutcome]) -> Policy:
    """A policy every one of these (audited) logs passes, with the margins above."""
    return learn_policy(outcomes)[0]


def learn_policy(outcomes: list[LogOutcome]) -> tuple[Policy, list[str]]:
    """The policy and one line per limit saying what it is and where it came from."""
    good = [o for o in outcomes if o.ok and o.audit is not None]
    if not good:
        raise ValueError("no log could be audited")
    per_camera: dict[str, dict[str, Seen]] = defaultdict(lambda: defaultdict(list))
    every: dict[str, Seen] = defaultdict(list)
    lidar: dict[str, Seen] = defaultdict(list)
    synced: dict[bool | None, list[str]] = defaultdict(list)
    for outcome in good:
        audit = outcome.audit or {}
        for cam in audit.get("cameras", []):
            for name, value in _camera_values(cam).items():
                if value is not None:
                    per_camera[cam["camera"]][name].append((value, _name(outcome)))
                    every[name].append((value, f"{cam['camera']} in {_name(outcome)}"))
        row = audit.get("lidar") or {}
        for name, value in (
            ("drop_rate", drop_rate(row)),
            ("rpm", row.get("rpm")),
            ("packets_per_revolution", row.get("packets_per_revolution")),
            ("duration_s", audit.get("duration_s")),
        ):
            if value is not None:
                lidar[name].append((float(value), _name(outcome)))
        synced[row.get("clock_synchronised")].append(_name(outcome))
    learned: list[str] = []
    topics = set.intersection(*(set(o.topics) for o in good))
    lidar_checks: dict[str, Any] = {}
    if lidar["drop_rate"]:
        worst, source = max(lidar["drop_rate"])
        lidar_checks["drop_rate"] = {"max": round(max(worst * 2, 0.001), 5), "severity": "warn"}
        learned.append(
            f"defaults.lidar.drop_rate: max {lidar_checks['drop_rate']['max']:g} (2 x the "
            f"worst, {worst:.3g} in {source}, at least 0.001) warn"
        )
    for name in ("rpm", "packets_per_revolution"):
        if lidar[name]:
            (lo, lo_src), (hi, hi_src) = min(lidar[name]), max(lidar[name])
            lidar_checks[name] = {
                "min": round(lo * 0.98, 2),
                "max": round(hi * 1.02, 2),
                "severity": "warn",
            }
            learned.append(
                f"defaults.lidar.{name}: {lidar_checks[name]['min']:g}..{lidar_checks[name]['max']:g}"
                f" (the good range {lo:.6g} ({lo_src})..{hi:.6g} ({hi_src}) +-2 %) warn"
            )
    if len(synced) == 1 and None not in synced:
        state = next(iter(synced))
        lidar_checks["clock_synchronised"] = {"expect": state, "severity": "warn"}
        learned.append(
            f"defaults.lidar.clock_synchronised: expect {str(state).lower()} (as all "
            f"{len(good)} good log(s) showed it) warn"
        )
    else:
        lidar_checks["clock_synchronised"] = None
        learned.append("defaults.lidar.clock_synchronised: off (the good logs disagree)")
    log_checks: dict[str, Any] = {"required_topics": {"topics": sorted(topics), "severity": "fail"}}
    learned.append(
        f"defaults.log.required_topics: the {len(topics)} topic(s) every good log holds fail"
    )
    if lidar["duration_s"]:
        shortest, source = min(lidar["duration_s"])
        log_checks["duration_s"] = {"min": round(shortest * 0.5, 3), "severity": "warn"}
        learned.append(
            f"defaults.log.duration_s: min {log_checks['duration_s']['min']:g} s (half the "
            f"shortest, {shortest:.4g} s in {source}) warn"
        )
    camera_defaults = _camera_limits(every, "defaults.camera", learned)
    for name in ("error_mean_us", "error_var_us2", "paired_fraction"):
        if camera_defaults.setdefault(name, None) is None:  # never measured: off
            learned.append(f"defaults.camera.{name}: off (no good log measured it)")
    cameras = {
        name: _camera_limits(values, f"cameras.{name}", learned)
        for name, values in sorted(per_camera.items())
    }
    raw = {
        "version": 1,
        "description": f"written by syncaudit gate --init from {len(good)} known-good log(s)",
        "defaults": {"camera": camera_defaults, "lidar": lidar_checks, "log": log_checks},
        "cameras": cameras,
    }
    return parse_policy(raw, "gate --init"), learned


INIT_HEADER = """\
# syncaudit gate policy, written by `syncaudit gate --init` from known-good logs.
# Margins (docs/fleet.md): time limits 1.5 x the worst good value + 50 us; Eq. 6 variance
# 2.25 x + 2500 us^2; paired fraction 0.9 x the lowest; drop rate 2 x the worst (>= 0.001);
# RPM and packets/rev the good range +-2 %; duration >= half the shortest; required topics
# those every good log had. Eq. 5/6, paired fraction, topics: fail; the rest: warn.
# Override per vehicle under `vehicles.<id>` and per camera under `cameras.<name>`.
"""


def init_policy_yaml(outcomes: list[LogOutcome], accepted: list[str] | None = None) -> str:
    """The policy file text for `gate --init`; `accepted` problems of the known-good logs
    (`fleet.init_review`) the user wrote it despite are kept in its header."""
    header = INIT_HEADER
    if accepted:
        header += "# WARNING: written although the known-good logs are not good (--accept-bad):\n"
        header += "".join(f"#   - {line}\n" for line in accepted)
    return policy_to_yaml(policy_from_outcomes(outcomes), header)
