"""Issue 23: the gate's Markdown names the missing topics, shows booleans as booleans and
says why a log with 0 failed checks failed; `info --json` carries the file's condition."""

from __future__ import annotations

from pathlib import Path

import pytest

from syncaudit.audit.inspect import inspect_log
from syncaudit.fleet.gate import GateOptions, run_gate
from syncaudit.fleet.policy import parse_policy

from .conftest import THREE_CAMERAS

REAL_VLP16 = Path("/work/shared/data/lidar/velodyne_vlp16/1673400471837873222")
LOOSE = {"camera": {"error_mean_us": {"max": 5000}, "error_var_us2": {"max": 1e8}}}


def test_missing_topics_and_flags_read_as_words(tmp_path: Path) -> None:
    policy = parse_policy(
        {
            "defaults": {
                **LOOSE,
                "log": {"required_topics": {"topics": ["/velodyne_packets", "/gps/fix"]}},
                "lidar": {"clock_synchronised": {"expect": False}},
            }
        },
        "p",
    )
    summary = tmp_path / "s.md"
    run_gate([str(THREE_CAMERAS)], policy, GateOptions(summary=summary, jobs=1))
    text = summary.read_text()
    assert "| log: required_topics | missing: /gps/fix | == 0 topics missing |" in text
    assert "| /velodyne_packets: clock_synchronised | true | == false |" in text
    body = text.split("\n", 1)[1]  # below the file's mark (`<!-- written by syncaudit ... -->`)
    assert "| 1 |" not in body and "1.0" not in body


@pytest.mark.skipif(not REAL_VLP16.is_dir(), reason="real recordings not mounted")
def test_a_lidar_only_log_says_why_it_failed(tmp_path: Path) -> None:
    summary, json_out = tmp_path / "s.md", tmp_path / "g.json"
    run = run_gate(
        [str(REAL_VLP16)],
        parse_policy({"defaults": LOOSE}, "p"),
        GateOptions(summary=summary, json_out=json_out, jobs=1),
    )
    (log,) = run.logs
    # Only a warn check failed (its clock is not synchronised): the verdict needs a reason.
    assert log.verdict == "fail" and [c.severity for c in log.failed_checks] == ["warn"]
    why = "no camera to judge in this log (a LiDAR-only log cannot pass the sync gate)"
    assert log.why_failed == why
    text = summary.read_text()
    assert f"| fail | verdict | {why} | |" in text
    assert f"| ❌ fail | 1 of {len(log.checks)} | {why} |" in text
    assert why in json_out.read_text()


def test_info_json_records_a_cut(tmp_path: Path) -> None:
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(THREE_CAMERAS.read_bytes()[:600_000])
    health = inspect_log(cut).to_dict()["health"]
    assert health["truncated"] is True and health["cut_at_byte"] == 597772
    assert inspect_log(THREE_CAMERAS).to_dict()["health"]["intact"] is True
