"""A camera analysis worker that dies mid-run (the OOM killer's SIGKILL) ends the audit with
one line naming the log and how the worker died, exit 130, no output and no worker left.

The kill is real: the CLI runs with each camera's analysis held in its forked worker, which
writes its pid first; the test SIGKILLs one of them while both are inside their camera.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from slowed_cli import foreground, reaped, survivors, worker_killed_line
from syncaudit.errors import EXIT_INTERRUPTED

REPO = Path(__file__).resolve().parents[2]
LOG = REPO / "sample_logs" / "vlp16_three_cameras.mcap"

_SCRIPT = """
import os, sys, time
from pathlib import Path
import syncaudit.audit.run as run

_audit = run._CameraJob.audit
marks = Path(sys.argv[1])


def held(self, index):
    (marks / f"{os.getpid()}.pid").write_text("")
    time.sleep(30.0)
    return _audit(self, index)


run._CameraJob.audit = held
from syncaudit.cli import main

sys.argv = ["syncaudit", *sys.argv[2:]]
main()
"""


def _pids(folder: Path, count: int, proc: subprocess.Popen[str]) -> list[int]:
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline and proc.poll() is None:
        pids = [int(p.stem) for p in folder.glob("*.pid")]
        if len(pids) >= count:
            return pids
        time.sleep(0.02)
    return []


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs Linux /proc")
def test_camera_worker_killed_mid_analysis_is_one_line_and_exit_130(tmp_path: Path) -> None:
    marks, out = tmp_path / "marks", tmp_path / "out"
    marks.mkdir()
    out.mkdir()
    json_out = out / "audit.json"
    argv = [
        "audit",
        str(LOG),
        "--rig",
        f"{LOG}.rig.yaml",
        "--jobs",
        "2",
        "--json-out",
        str(json_out),
    ]
    proc = subprocess.Popen(
        foreground([sys.executable, "-c", _SCRIPT, str(marks), *argv]),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,
        text=True,
    )
    with reaped(proc):
        workers = _pids(marks, 2, proc)
        assert len(workers) == 2, "two cameras were never analysed side by side"
        os.kill(workers[0], signal.SIGKILL)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == EXIT_INTERRUPTED, err
    assert err.strip().splitlines() == [worker_killed_line(LOG, "a camera analysis process")]
    assert not list(out.iterdir())  # neither the JSON nor a temporary of it
    assert survivors(workers) == []
