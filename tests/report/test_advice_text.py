"""The recommendation (issue 23) as one sentence, in the HTML report and the gate's Markdown;
audits without one show nothing and break nothing."""

from __future__ import annotations

from typing import Any

import pytest

from syncaudit.audit.run import AuditResult, CameraAudit
from syncaudit.fleet.inputs import LogJob
from syncaudit.fleet.record import JudgedLog
from syncaudit.fleet.run_summary import render_markdown, summary_dict
from syncaudit.report.advice_text import advice_sentence, needs_action
from syncaudit.report.html import render_audit_html

SHIFT: dict[str, Any] = {
    "action": "shift_trigger",
    "shift_us": -1500.4,
    "expected_error_mean_us": 336.6,
    "expected_error_var_us2": 12000.0,
    "current_error_mean_us": 1605.04,
    "floor_us": 290.2,
    "why": "the error is a constant 1.5 ms offset.",
}


def test_sentences_for_each_action() -> None:
    assert advice_sentence("front", SHIFT) == (
        "front: shift the trigger by -1500.4 µs (Eq. 5 1605 µs now, 337 µs expected, "
        "floor 290 µs): the error is a constant 1.5 ms offset."
    )
    per_frame = {**SHIFT, "action": "per_frame_compensation", "shift_us": None, "floor_us": None}
    assert advice_sentence("rear", per_frame) == (
        "rear: compensate per frame (no constant delay removes this error) (Eq. 5 1605 µs now, "
        "337 µs expected): the error is a constant 1.5 ms offset."
    )
    assert needs_action(SHIFT) and not needs_action({**SHIFT, "action": "none"})
    assert advice_sentence("x", None) is None and not needs_action(None)
    assert advice_sentence("x", {"action": "reboot"}) is None


def test_markdown_leads_with_the_advice() -> None:
    log = JudgedLog(
        job=LogJob(path="up/a.mcap"),
        key="k",
        fingerprint="f",
        rig_fingerprint=None,
        policy_fingerprint="p",
        tool_version="t",
        verdict="pass",
        advice={"front": SHIFT, "rear": {**SHIFT, "action": "none"}},
    )
    text = render_markdown([log])
    assert text.index("## Advice") < text.index("## All logs")
    assert "- `up/a.mcap`: front: shift the trigger by -1500.4 µs" in text
    assert "rear:" not in text  # 'none' asks for nothing
    assert summary_dict([log], "p")["logs"][0]["advice"]["front"] == SHIFT
    plain = JudgedLog(
        job=LogJob(path="up/b.mcap"),
        key="k2",
        fingerprint="f",
        rig_fingerprint=None,
        policy_fingerprint="p",
        tool_version="t",
        verdict="pass",
    )
    assert "## Advice" not in render_markdown([plain])
    assert "advice" not in summary_dict([plain], "p")["logs"][0]


def test_html_shows_the_advice_where_the_audit_has_it(
    audit: AuditResult, monkeypatch: pytest.MonkeyPatch
) -> None:
    plain = CameraAudit.to_dict

    def without_advice(self: CameraAudit) -> dict[str, Any]:
        data = plain(self)
        data.pop("recommendation", None)
        return data

    monkeypatch.setattr(CameraAudit, "to_dict", without_advice)
    assert 'class="advice"' not in render_audit_html(audit)  # an audit without advice: none

    def with_advice(self: CameraAudit) -> dict[str, Any]:
        return {**plain(self), "recommendation": SHIFT}

    monkeypatch.setattr(CameraAudit, "to_dict", with_advice)
    page = render_audit_html(audit)
    assert page.count('<p class="advice"><b>Advice</b> — ') == len(audit.cameras)
    assert "front: shift the trigger by -1500.4 µs" in page
