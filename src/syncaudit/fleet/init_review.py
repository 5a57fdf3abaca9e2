"""`gate --init`'s doubts: why the "known-good" logs it was given may not be good.

A policy learnt from bad logs passes bad logs: from the sample logs, which `audit` calls
FAIL, it learnt `error_mean_us max 2514.9`; from LiDAR-only logs it switched every camera
check off; from logs that disagree on the LiDAR clock it dropped that check. Each such
problem is one line here; `gate --init` refuses to write the policy while there are any,
unless told to accept them (then each is warned and kept in the policy's header).
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

from syncaudit.fleet.checks import evaluate
from syncaudit.fleet.job import LogOutcome
from syncaudit.fleet.policy import Policy


def init_problems(outcomes: list[LogOutcome]) -> list[str]:
    """One line per reason to doubt the known-good logs (empty: they look good)."""
    good = [o for o in outcomes if o.ok and o.audit is not None]
    problems: list[str] = []
    defaults = Policy()
    clocks: dict[bool, list[str]] = defaultdict(list)
    for outcome in good:
        name = Path(outcome.job.path).name
        audit = outcome.audit or {}
        if not audit.get("cameras"):
            problems.append(
                f"{name}: no camera (a LiDAR-only log?): every camera check would be learnt "
                "as off, so the policy would judge no camera"
            )
        failed = [c for c in evaluate(outcome, defaults, outcome.job.vehicle) if not c.passed]
        # The file's condition first: a cut log's camera figures are of a part of it.
        hard = sorted((c for c in failed if c.severity == "fail"), key=lambda c: c.scope != "log")
        if hard:
            shown = "; ".join(
                f"{c.subject}: {c.message}" if c.scope != "log" else c.message for c in hard[:4]
            )
            more = f" (+{len(hard) - 4} more)" if len(hard) > 4 else ""
            problems.append(f"{name}: fails the default thresholds: {shown}{more}")
        if audit.get("verdict") == "not judged":
            reasons = "; ".join(audit.get("not_judged") or [])
            problems.append(f"{name}: the audit could not judge it ({reasons})")
        synced = (audit.get("lidar") or {}).get("clock_synchronised")
        if synced is not None:
            clocks[bool(synced)].append(name)
    if len(clocks) > 1:
        problems.append(
            "the logs disagree on the LiDAR clock: synchronised in "
            f"{', '.join(clocks[True])}, not in {', '.join(clocks[False])}; the clock check "
            "would be learnt as off"
        )
    return problems
