"""The results database under two concurrent writer processes: no corruption, no lost row."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import duckdb

from syncaudit.fleet.checks import CheckResult
from syncaudit.fleet.database import ResultsDB
from syncaudit.fleet.inputs import LogJob
from syncaudit.fleet.job import LogOutcome
from syncaudit.fleet.record import JudgedLog

BATCHES, PER_BATCH = 6, 4


WRITER = """
import json, sys
sys.path.insert(0, sys.argv[4])
from test_database import _writer
_writer(sys.argv[1], sys.argv[2], json.load(open(sys.argv[3])))
"""


def _writer(db_path: str, name: str, audit: dict[str, object]) -> None:
    """One `gate` run's worth of writes: many short transactions."""
    db = ResultsDB(db_path, lock_timeout_s=60)
    for batch in range(BATCHES):
        logs = []
        for index in range(PER_BATCH):
            key = f"{name}-{batch}-{index}"
            logs.append(
                JudgedLog(
                    job=LogJob(path=f"/fleet/{name}/{batch}/{index}.mcap", vehicle=name),
                    key=key,
                    fingerprint=key,
                    rig_fingerprint=None,
                    policy_fingerprint="p",
                    tool_version="t",
                    verdict="pass",
                    checks=[
                        CheckResult(
                            "camera",
                            "front",
                            "error_mean_us",
                            1.0,
                            "<= 2",
                            "us",
                            "fail",
                            True,
                            "ok",
                        )
                    ],
                    audit=audit,
                    start_ns=1_700_000_000_000_000_000 + batch,
                )
            )
        db.write(logs)


def test_two_concurrent_writer_processes_lose_nothing(
    tmp_path: Path, three_cameras_outcome: LogOutcome
) -> None:
    db_path = str(tmp_path / "fleet.duckdb")
    audit = tmp_path / "audit.json"
    audit.write_text(json.dumps(three_cameras_outcome.audit))
    here = str(Path(__file__).parent)
    # Two interpreters, as two `gate` runs on one database.
    writers = [
        subprocess.Popen([sys.executable, "-c", WRITER, db_path, name, str(audit), here])
        for name in ("car1", "car2")
    ]
    for process in writers:
        assert process.wait(timeout=120) == 0
    expected = 2 * BATCHES * PER_BATCH
    with duckdb.connect(db_path, read_only=True) as con:
        assert con.execute("SELECT count(*) FROM logs").fetchone() == (expected,)
        assert con.execute("SELECT count(*) FROM cameras").fetchone() == (expected * 3,)
        assert con.execute("SELECT count(*) FROM lidars").fetchone() == (expected,)
        assert con.execute("SELECT count(*) FROM checks").fetchone() == (expected,)
        per_vehicle = con.execute(
            "SELECT vehicle, count(*) FROM logs GROUP BY 1 ORDER BY 1"
        ).fetchall()
    assert per_vehicle == [("car1", expected // 2), ("car2", expected // 2)]
    # Writing the same verdicts again replaces them (one row per key, never duplicates).
    _writer(db_path, "car1", three_cameras_outcome.audit)  # type: ignore[arg-type]
    with duckdb.connect(db_path, read_only=True) as con:
        assert con.execute("SELECT count(*) FROM logs").fetchone() == (expected,)
