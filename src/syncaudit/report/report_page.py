"""One page with the audit and/or the calibration of a log (`audit --html`, `calib --html`).

Above both parts' renderers (`report.html` for the audit, `report.calib_section` for the
calibration), so neither imports the other.
"""

from __future__ import annotations

from syncaudit.audit.run import AuditResult
from syncaudit.calib.result import CalibrationResult
from syncaudit.report.calib_section import html_section
from syncaudit.report.html import audit_sections, page, time_origin_ns


def render_report_html(
    audit: AuditResult | None = None, calibration: CalibrationResult | None = None
) -> str:
    """One page with the audit and/or the calibration of a log."""
    if audit is None and calibration is None:
        raise ValueError("render_report_html needs an audit or a calibration result")
    parts = []
    if audit is not None:
        parts.append(audit_sections(audit))
    if calibration is not None:
        parts.append(html_section(calibration))
    title = audit.path if audit is not None else calibration.log if calibration else ""
    return page(
        f"syncaudit: {title}",
        "".join(parts),
        t0_ns=time_origin_ns(audit) if audit is not None else None,
    )


def render_calibration_html(result: CalibrationResult) -> str:
    """A self-contained HTML page of a calibration result (what `calib --html` writes)."""
    return render_report_html(None, result)
