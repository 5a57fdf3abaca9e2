"""Markdown and JSON summaries of a gate run.

The JSON summary is deterministic: logs sorted by path, checks by scope/subject/check,
keys sorted, no timings or timestamps, so two runs over the same logs with the same tool,
rigs and policy (locally or on a cluster) give byte-identical files.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Sequence
from typing import Any

from syncaudit import __version__
from syncaudit.fleet.checks import shown_limit, shown_value
from syncaudit.fleet.record import JudgedLog
from syncaudit.report.advice_text import advice_sentence, needs_action
from syncaudit.writers.provenance import marked_json

VERDICTS = ("fail", "error", "warn", "pass")
SUMMARY_VERSION = 1


def summary_dict(
    logs: list[JudgedLog], policy_fingerprint: str, warnings: Sequence[str] = ()
) -> dict[str, Any]:
    """The JSON summary as a dict (`warnings` only when there are some)."""
    counts = Counter(log.verdict for log in logs)
    extra: dict[str, Any] = {"warnings": sorted(warnings)} if warnings else {}
    return {
        **extra,
        "summary_version": SUMMARY_VERSION,
        "tool_version": __version__,
        "policy_fingerprint": policy_fingerprint,
        "counts": {v: counts.get(v, 0) for v in VERDICTS},
        "logs": [
            {
                "path": log.path,
                "vehicle": log.job.vehicle,
                "tags": sorted(log.job.tags),
                "fingerprint": log.fingerprint,
                "rig_fingerprint": log.rig_fingerprint,
                "verdict": log.verdict,
                "error": log.error,
                "error_code": log.error_code,
                "checks": [c.to_dict() for c in log.checks],
                "health": log.health,
                **({"advice": log.advice} if log.advice else {}),
                **({"why_failed": log.why_failed} if log.why_failed else {}),
                **({"remote_read": log.remote_read} if log.remote_read else {}),
            }
            for log in sorted(logs, key=lambda item: item.path)
        ],
    }


def render_json(
    logs: list[JudgedLog], policy_fingerprint: str, warnings: Sequence[str] = ()
) -> str:
    """The JSON summary text (sorted keys, 2-space indent, trailing newline)."""
    data = summary_dict(logs, policy_fingerprint, warnings)
    ordered = json.loads(json.dumps(data, sort_keys=True, allow_nan=False))
    return json.dumps(marked_json(ordered), indent=2, allow_nan=False) + "\n"


def _md(text: object) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


MAX_ADVICE_LINES = 30


def _advice_lines(ranked: list[JudgedLog]) -> list[str]:
    """`## Advice`: one sentence per camera whose recommendation asks for a change."""
    advice = [
        f"- `{_md(log.path)}`: {_md(sentence)}"
        for log in ranked
        if log.verdict != "error"
        for camera, rec in sorted(log.advice.items())
        if needs_action(rec) and (sentence := advice_sentence(camera, rec))
    ]
    if not advice:
        return []
    more = len(advice) - MAX_ADVICE_LINES
    tail = [f"- … and {more} more (see the JSON summary)"] if more > 0 else []
    return ["## Advice", "", *advice[:MAX_ADVICE_LINES], *tail, ""]


def render_markdown(logs: list[JudgedLog], warnings: Sequence[str] = ()) -> str:
    """A Markdown page for a CI job summary: counts, then failing logs and checks first."""
    counts = Counter(log.verdict for log in logs)
    icon = {"fail": "❌", "error": "💥", "warn": "⚠️", "pass": "✅"}
    lines = [
        "# syncaudit gate",
        "",
        " · ".join(f"{icon[v]} **{counts.get(v, 0)}** {v}" for v in VERDICTS)
        + f" — {len(logs)} log(s)",
        "",
    ]
    order = {v: i for i, v in enumerate(VERDICTS)}
    ranked = sorted(logs, key=lambda log: (order[log.verdict], log.path))
    lines += _advice_lines(ranked)
    bad = [log for log in ranked if log.verdict in ("fail", "error")]
    if bad:
        lines += ["## Failing logs", "", "| log | vehicle | verdict | check | measured | limit |"]
        lines.append("| --- | --- | --- | --- | --- | --- |")
        for log in bad:
            if log.error is not None:
                lines.append(
                    f"| `{_md(log.path)}` | {_md(log.job.vehicle or '')} | error | audit | "
                    f"{_md(log.error)} | |"
                )
                continue
            failed = log.failed_checks or []
            if log.why_failed:
                lines.append(
                    f"| `{_md(log.path)}` | {_md(log.job.vehicle or '')} | fail | verdict | "
                    f"{_md(log.why_failed)} | |"
                )
            for check in failed:
                lines.append(
                    f"| `{_md(log.path)}` | {_md(log.job.vehicle or '')} | {check.severity} | "
                    f"{_md(check.subject)}: {check.check} | {_md(shown_value(check))} | "
                    f"{_md(shown_limit(check))} |"
                )
        lines.append("")
    lines += ["## All logs", "", "| log | vehicle | verdict | checks failed | note |"]
    lines.append("| --- | --- | --- | --- | --- |")
    for log in ranked:
        notes = ["unchanged, verdict from the database"] if log.skipped else []
        notes += (log.health or {}).get("problems") or []
        notes += [log.why_failed] if log.why_failed else []
        note = "; ".join(notes)
        n_failed = len(log.failed_checks)
        lines.append(
            f"| `{_md(log.path)}` | {_md(log.job.vehicle or '')} | {icon[log.verdict]} {log.verdict} | "
            f"{n_failed} of {len(log.checks)} | {note} |"
        )
    if warnings:
        lines += ["", "## Warnings", ""] + [f"- {_md(w)}" for w in sorted(warnings)]
    return "\n".join(lines) + "\n"
