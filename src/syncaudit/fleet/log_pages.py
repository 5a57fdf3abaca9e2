"""Per-log HTML reports of a gate run (the audit report plus the policy checks) and an index."""

from __future__ import annotations

import html
import os
import re
from collections import Counter
from typing import Any

from syncaudit.fleet.checks import CheckResult, shown_limit, shown_value
from syncaudit.fleet.job import ReportDraft
from syncaudit.fleet.record import JudgedLog
from syncaudit.writers.provenance import HTML_MARK

_STYLE = """
body{font:14px/1.45 system-ui,sans-serif;margin:2rem auto;max-width:1100px;color:#222}
table{border-collapse:collapse;margin:.5rem 0}td,th{border:1px solid #ccc;padding:.25rem .6rem;text-align:left}
th{background:#f3f3f3}.pass{color:#176f2c;font-weight:600}.fail,.error{color:#b00020;font-weight:600}
.warn{color:#8a5a00;font-weight:600}.num{text-align:right;font-variant-numeric:tabular-nums}
"""


def _e(value: object) -> str:
    return html.escape(str(value))


def checks_section(checks: list[CheckResult]) -> str:
    """An HTML section listing the policy checks of one log, failures first."""
    if not checks:
        return "<h2>Policy checks</h2><p>No policy check applied.</p>"
    ordered = sorted(checks, key=lambda c: (c.passed, c.severity != "fail", c.scope, c.subject))
    rows = "".join(
        f"<tr><td>{_e(c.scope)}</td><td>{_e(c.subject)}</td><td>{_e(c.check)}</td>"
        f"<td class=num>{_e(shown_value(c))}</td>"
        f"<td>{_e(shown_limit(c))}</td><td>{_e(c.severity)}</td>"
        f'<td class="{"pass" if c.passed else c.severity}">{"pass" if c.passed else "FAIL"}</td></tr>'
        for c in ordered
    )
    return (
        "<h2>Policy checks</h2><table><tr><th>scope</th><th>subject</th><th>check</th>"
        f"<th>value</th><th>limit</th><th>severity</th><th>result</th></tr>{rows}</table>"
    )


_GATE_CSS = {"pass": "pass", "warn": "notjudged", "fail": "fail", "error": "fail"}


def gate_verdict_section(
    verdict: str, checks: list[CheckResult], audit: dict[str, Any] | None = None
) -> str:
    """The page's lead: the policy's verdict, why (failed checks, the file's condition, or
    no camera to judge), and what the audit's own verdict below means."""
    failed = sorted(
        (c for c in checks if not c.passed), key=lambda c: (c.severity != "fail", c.scope)
    )
    why = [f"{c.subject}: {c.message}" for c in failed]
    problems = ((audit or {}).get("health") or {}).get("problems") or []
    why += [f"log file: {p}" for p in problems if not any(p in w for w in why)]
    if verdict == "fail" and not any(c.severity == "fail" for c in failed):
        why.append("no camera to judge in this log" if audit is not None else "nothing judged it")
    items = "".join(f"<li>{_e(line)}</li>" for line in why)
    own = (audit or {}).get("verdict")
    note = (
        f"<p>The audit's own verdict below ({_e(own)}) is against the rig's thresholds; "
        "the gate judges by the policy's checks.</p>"
        if own is not None
        else ""
    )
    return (
        f'<h1>syncaudit gate: <span class="{_GATE_CSS.get(verdict, "warn")}" '
        f'id="gate-verdict">{_e(verdict.upper())}</span></h1>'
        + (f"<ul>{items}</ul>" if items else "<p>Every policy check passed.</p>")
        + note
    )


def render_log_page(
    draft: ReportDraft,
    checks: list[CheckResult],
    verdict: str = "",
    audit: dict[str, Any] | None = None,
) -> str:
    """A judged log's report page: the policy's verdict and checks first, then the
    worker's sections (the audit, with its own verdict second; the calibration)."""
    from syncaudit.report.html import page

    lead = gate_verdict_section(verdict, checks, audit) if verdict else ""
    return page(draft.title, lead + checks_section(checks) + draft.body, t0_ns=draft.t0_ns)


def report_name(log: JudgedLog) -> str:
    """File name of a log's report: readable stem plus the verdict key (unique per verdict)."""
    return report_file_name(log.path, log.key)


def report_file_name(path: str, key: str) -> str:
    """File name of the report of the log at `path` judged under `key`."""
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", os.path.basename(path.rstrip("/")))[:80]
    return f"{stem}-{key[:10]}.html"


def render_error_page(log: JudgedLog) -> str:
    """The report of a log that could not be audited: its error."""
    return (
        "<!doctype html><html lang=en><head><meta charset=utf-8>"
        + HTML_MARK
        + f"<title>syncaudit: {_e(log.path)}</title><style>{_STYLE}</style></head><body>"
        f'<h1>syncaudit gate: <span class="error">ERROR</span></h1><p>{_e(log.path)}</p>'
        f"<p>{_e(log.error)}</p></body></html>\n"
    )


def render_index(logs: list[JudgedLog], links: dict[str, str]) -> str:
    """The index page: verdict counts and one row per log, failing first, linked to reports."""
    counts = Counter(log.verdict for log in logs)
    order = {"fail": 0, "error": 1, "warn": 2, "pass": 3}
    rows = []
    for log in sorted(logs, key=lambda item: (order[item.verdict], item.path)):
        href = links.get(log.key)
        name = f'<a href="{_e(href)}">{_e(log.path)}</a>' if href else _e(log.path)
        failed = ", ".join(f"{c.subject}: {c.check}" for c in log.failed_checks)
        failed = "; ".join(x for x in (failed, log.error or "", log.why_failed) if x)
        rows.append(
            f"<tr><td>{name}</td><td>{_e(log.job.vehicle or '')}</td>"
            f'<td class="{log.verdict}">{log.verdict}</td><td>{_e(failed)}</td></tr>'
        )
    summary = " · ".join(f"{counts.get(v, 0)} {v}" for v in ("fail", "error", "warn", "pass"))
    return (
        "<!doctype html><html lang=en><head><meta charset=utf-8>"
        + HTML_MARK
        + "<title>syncaudit gate</title>"
        f"<style>{_STYLE}</style></head><body><h1>syncaudit gate</h1><p>{summary}</p>"
        "<table><tr><th>log</th><th>vehicle</th><th>verdict</th><th>failed checks / error</th></tr>"
        + "".join(rows)
        + "</table></body></html>\n"
    )
