"""What an audit imports, and when: the start-up a reader worker pool waits for stays small.

`syncaudit.audit.run` itself leaves out the analysis (imported while workers read) and rich
(the CLI imports it, through `meanwhile`, only to print tables); `meanwhile` runs once.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

SAMPLE = Path(__file__).resolve().parents[2] / "sample_logs" / "vlp16_three_cameras.mcap"

SCRIPT = """
import sys
import syncaudit.audit.run
from syncaudit.rig import load_rig

later = ("syncaudit.analysis.controller", "syncaudit.analysis.sync", "rich", "numpy.ma")
print(sorted(m for m in later if m in sys.modules))
calls = []
result = syncaudit.audit.run.audit_log(
    sys.argv[1], load_rig(sys.argv[1] + ".rig.yaml"), jobs=1,
    meanwhile=lambda: calls.append("syncaudit.analysis.sync" in sys.modules),
)
print(calls, result.verdict)
"""


def test_audit_imports_analysis_and_rich_only_when_needed() -> None:
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(SAMPLE)], capture_output=True, text=True, check=True
    )
    before, during = done.stdout.splitlines()
    assert before == "[]"
    # The caller's work ran once, after the analysis' imports, and the audit went on.
    calls, verdict = during.split("] ")
    assert calls == "[True" and verdict in ("pass", "fail", "not judged")


CLI_SCRIPT = """
import os, sys
from syncaudit.cli import main

real_exit = os._exit
def report(code):
    shown = ("rich", "syncaudit.report.console")
    sys.stderr.write(str(sorted(m for m in shown if m in sys.modules)) + "\\n")
    sys.stderr.flush()
    real_exit(code)
os._exit = report
sys.argv = ["syncaudit", *sys.argv[1:]]
main()
"""


def test_json_audit_does_not_import_rich() -> None:
    """`audit --json` prints no table: rich (~20 ms of start-up) is never imported."""
    argv = ["audit", str(SAMPLE), "--rig", f"{SAMPLE}.rig.yaml", "--json"]
    done = subprocess.run(
        [sys.executable, "-c", CLI_SCRIPT, *argv],
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert done.stderr.strip().splitlines()[-1] == "[]"


PACKAGE_API = """
import sys
import syncaudit.audit
print(sorted(m for m in ("syncaudit.audit.run", "syncaudit.audit.inspect") if m in sys.modules))
from syncaudit.audit import audit_log, guess_rig, inspect_log
print(audit_log.__module__, inspect_log.__module__, guess_rig.__module__)
try:
    syncaudit.audit.no_such_name
except AttributeError as exc:
    print(exc)
"""


def test_the_package_exports_the_api_when_first_used() -> None:
    """`from syncaudit.audit import audit_log` works (the README's library use); importing
    the package alone imports none of its steps."""
    done = subprocess.run(
        [sys.executable, "-c", PACKAGE_API], capture_output=True, text=True, check=True
    )
    before, homes, missing = done.stdout.splitlines()
    assert before == "[]"
    assert homes == "syncaudit.audit.run syncaudit.audit.inspect syncaudit.audit.rig_guess"
    assert "no_such_name" in missing
