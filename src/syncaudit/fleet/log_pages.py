"""Per-log HTML reports of a gate run (the audit report plus the policy checks) and an index."""

from __future__ import annotations

import html
import os
import re
from collections import Counter

from syncaudit.fleet.checks import CheckResult
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
        f"<td class=num>{'-' if c.value is None else f'{c.value:.6g}'}</td>"
        f"<td>{_e(c.limit)} {_e(c.unit)}</td><td>{_e(c.severity)}</td>"
        f'<td class="{"pass" if c.passed else c.severity}">{"pass" if c.passed else "FAIL"}</td></tr>'
        for c in ordered
    )
    return (
        "<h2>Policy checks</h2><table><tr><th>scope</th><th>subject</th><th>check</th>"
        f"<th>value</th><th>limit</th><th>severity</th><th>result</th></tr>{rows}</table>"
    )


def render_log_page(draft: ReportDraft, checks: list[CheckResult]) -> str:
    """A judged log's report page: the worker's sections, then its policy checks."""
    from syncaudit.report.html import page

    return page(draft.title, draft.body + checks_section(checks), t0_ns=draft.t0_ns)


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
        failed = ", ".join(f"{c.subject}: {c.check}" for c in log.failed_checks) or (
            log.error or ""
        )
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
