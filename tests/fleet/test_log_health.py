"""Issue 23 finding 4: a damaged upload is a recorded condition of the log, never a silent pass.

`head -c 600000 vlp16_three_cameras.mcap > cut.mcap` passed a gate whose policy the whole
log passes, and the JSON summary, JUnit and Markdown said nothing of the cut.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml
from mcap.records import Channel, Message, Schema

from mcap_copy import copy_mcap
from syncaudit.audit.health import log_health
from syncaudit.fleet.gate import GateOptions, run_gate
from syncaudit.fleet.init_policy import policy_from_outcomes
from syncaudit.fleet.policy import Policy, parse_policy, policy_to_yaml
from syncaudit.logs.model import LogWarning

from .conftest import THREE_CAMERAS

CUT_BYTES = 600_000


@pytest.fixture(scope="module")
def uploads(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The whole sample, its first 600000 bytes, and a copy with damaged exposures."""
    root = tmp_path_factory.mktemp("up")
    whole = root / "whole.mcap"
    whole.symlink_to(THREE_CAMERAS)
    cut = root / "cut.mcap"
    cut.write_bytes(THREE_CAMERAS.read_bytes()[:CUT_BYTES])

    def cut_front_exposures(_schema: Schema, channel: Channel, message: Message) -> bytes:
        if channel.topic == "/cameras/front/exposure" and message.sequence % 5 == 0:
            return message.data[:7]
        return message.data

    damaged = copy_mcap(THREE_CAMERAS, root / "damaged.mcap", change=cut_front_exposures)
    for path in (whole, cut, damaged):
        (root / f"{path.name}.rig.yaml").symlink_to(f"{THREE_CAMERAS}.rig.yaml")
    return {"whole": whole, "cut": cut, "damaged": damaged}


@pytest.fixture(scope="module")
def learned(uploads: dict[str, Path]) -> Policy:
    """The policy `gate --init` learns from the whole sample (which it passes)."""
    from syncaudit.fleet.inputs import LogJob
    from syncaudit.fleet.job import JobOptions, run_log_job

    path = uploads["whole"]
    outcome = run_log_job(LogJob(str(path), rig_path=f"{path}.rig.yaml"), JobOptions())
    return policy_from_outcomes([outcome])


def test_a_cut_upload_fails_and_every_output_says_where(
    uploads: dict[str, Path], learned: Policy, tmp_path: Path
) -> None:
    options = GateOptions(
        db=tmp_path / "r.duckdb",
        junit=tmp_path / "j.xml",
        summary=tmp_path / "s.md",
        json_out=tmp_path / "g.json",
        jobs=1,
    )
    run = run_gate([str(uploads["whole"]), str(uploads["cut"])], learned, options)
    logs = {Path(log.path).name: log for log in run.logs}
    assert logs["whole.mcap"].verdict == "pass"
    cut = logs["cut.mcap"]
    assert cut.verdict == "fail" and run.exit_code == 10
    assert [(c.scope, c.check) for c in cut.failed_checks] == [("log", "truncated")]

    summary = json.loads((tmp_path / "g.json").read_text())
    by_name = {Path(item["path"]).name: item for item in summary["logs"]}
    health = by_name["cut.mcap"]["health"]
    assert health["truncated"] is True and health["intact"] is False
    assert 0 < health["cut_at_byte"] <= CUT_BYTES
    assert by_name["whole.mcap"]["health"]["intact"] is True

    junit = (tmp_path / "j.xml").read_text()
    assert 'testcase name="log: truncated" classname="' in junit
    assert f"truncated = true: cut off at byte {health['cut_at_byte']}" in junit

    markdown = (tmp_path / "s.md").read_text()
    assert "| log: truncated | true | == false |" in markdown
    assert f"cut off at byte {health['cut_at_byte']}" in markdown

    import duckdb

    con = duckdb.connect(str(tmp_path / "r.duckdb"), read_only=True)
    rows = dict(con.execute("SELECT path, intact FROM logs").fetchall())
    stored = con.execute("SELECT health FROM logs WHERE NOT intact").fetchone()
    con.close()
    assert {Path(p).name: v for p, v in rows.items()} == {"whole.mcap": True, "cut.mcap": False}
    assert stored is not None and json.loads(stored[0])["cut_at_byte"] == health["cut_at_byte"]


def test_a_policy_may_only_warn_of_a_cut_but_still_records_it(
    uploads: dict[str, Path], learned: Policy, tmp_path: Path
) -> None:
    data = yaml.safe_load(policy_to_yaml(learned))
    data["defaults"]["log"]["truncated"] = {"severity": "warn"}
    policy = parse_policy(data, "p")
    run = run_gate([str(uploads["cut"])], policy, GateOptions(summary=tmp_path / "s.md", jobs=1))
    (log,) = run.logs
    assert log.verdict == "warn" and run.exit_code == 0
    assert "cut off at byte" in (tmp_path / "s.md").read_text()


def test_damaged_messages_are_counted_per_topic(
    uploads: dict[str, Path], learned: Policy, tmp_path: Path
) -> None:
    run = run_gate([str(uploads["damaged"])], learned, GateOptions(jobs=1))
    (log,) = run.logs
    assert log.health is not None
    counts = log.health["damaged_messages"]
    assert list(counts) == ["/cameras/front/exposure"] and counts["/cameras/front/exposure"] > 5
    (check,) = [c for c in log.checks if c.check == "damaged_messages"]
    assert not check.passed and check.severity == "warn"
    assert check.value == counts["/cameras/front/exposure"]
    assert check.message.endswith(f"/cameras/front/exposure: {counts['/cameras/front/exposure']}")


def test_health_reads_every_reader_code() -> None:
    health = log_health(
        [
            LogWarning("rosbag1-truncated", "x.bag: ROS 1 bag cut off at byte 4096 (...)"),
            LogWarning("rosbag1-no-index", "y.bag: read by scanning"),
            LogWarning("rosbag1-mixed-types", "not a condition of the file"),
        ],
        [
            "camera front: 3 damaged messages skipped on /a (first at ...)",
            "2 damaged messages skipped on /b (shared by cameras x, y) (first at ...)",
            "camera rear: 1 damaged message skipped on /a (first at ...)",
            "an unrelated warning",
        ],
    )
    assert health.truncated and health.cut_at_byte == 4096 and health.missing_index
    assert health.damaged_messages == {"/a": 4, "/b": 2} and health.damaged_total == 6
    assert health.problems[0] == "cut off at byte 4096"
    assert len(health.notes) == 5 and not health.intact
    assert log_health([], []).intact


def test_messages_on_undeclared_channels_are_damage() -> None:
    """Messages skipped because the file never declared their channel were lost."""
    health = log_health([LogWarning("mcap-unknown-channel", "x.mcap: ... id 7 skipped")])
    assert health.status == "damaged" and not health.intact
    assert health.damaged == ("x.mcap: ... id 7 skipped",)


def test_the_gate_report_leads_with_the_policy_verdict(
    uploads: dict[str, Path], learned: Policy, tmp_path: Path
) -> None:
    """Finding 6: a log the gate passes opened with a red "syncaudit audit: FAIL"."""
    import re

    run = run_gate(
        [str(uploads["whole"]), str(uploads["cut"])],
        learned,
        GateOptions(html_dir=tmp_path / "html", jobs=1),
    )
    pages = {Path(log.path).name: Path(log.report or "").read_text() for log in run.logs}
    whole = pages["whole.mcap"]
    (first,) = re.findall(r"<h1>(.*?)</h1>", whole)  # one title: the gate's
    assert first == 'syncaudit gate: <span class="pass" id="gate-verdict">PASS</span>'
    own = "The audit's own verdict (the rig's thresholds, not the policy's): "
    assert f'<h2>{own}<span class="fail" id="verdict">FAIL</span></h2>' in whole
    assert whole.index("gate-verdict") < whole.index("Policy checks") < whole.index(own)
    cut = pages["cut.mcap"]
    assert 'id="gate-verdict">FAIL</span></h1><ul><li>log: truncated = true: cut off at' in cut
    assert "<td>truncated</td><td class=num>true</td><td>== false</td>" in cut


def test_a_database_written_before_the_health_columns_gets_them(
    uploads: dict[str, Path], learned: Policy, tmp_path: Path
) -> None:
    import duckdb

    from syncaudit.fleet.schema import ADDED_COLUMNS, create_statements

    db = tmp_path / "old.duckdb"
    con = duckdb.connect(str(db))
    for statement in create_statements():
        if not statement.startswith("ALTER"):
            con.execute(statement)
    for name, _ in ADDED_COLUMNS:  # as the first layout had it
        con.execute(f'ALTER TABLE logs DROP COLUMN "{name}"')
    con.close()
    run_gate([str(uploads["cut"])], learned, GateOptions(db=db, jobs=1))
    con = duckdb.connect(str(db), read_only=True)
    row = con.execute("SELECT intact, json_extract(health, '$.truncated') FROM logs").fetchone()
    con.close()
    assert row == (False, "true")
