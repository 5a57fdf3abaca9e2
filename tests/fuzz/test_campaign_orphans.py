"""The campaign's orphan check: a worker left running is one; a worker already killed,
which a loaded machine has not yet let exit, is not (it counted as one, by timing)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from campaign import _dying, _session_members


def _fields(pid: int) -> list[str]:
    return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()


def test_a_running_process_left_in_the_session_is_an_orphan() -> None:
    child = subprocess.Popen(
        [sys.executable, "-c", "import time; time.sleep(60)"], start_new_session=True
    )
    try:
        assert _session_members(child.pid) == [child.pid]
        assert not _dying(Path(f"/proc/{child.pid}"), _fields(child.pid))
    finally:
        child.kill()
        child.wait()
    assert _session_members(child.pid) == []


def test_a_killed_or_exiting_process_is_not(tmp_path: Path) -> None:
    """As /proc shows a process the kernel has doomed but not yet run: SIGKILL pending
    (for the thread or the whole process), or PF_EXITING in its flags."""
    me = _fields(os.getpid())
    status = Path(f"/proc/{os.getpid()}/status").read_text()
    assert not _dying(Path(f"/proc/{os.getpid()}"), me)
    for key in ("SigPnd", "ShdPnd"):
        doomed = tmp_path / key
        doomed.mkdir()
        lines = [
            f"{key}:\t0000000000000100" if line.startswith(f"{key}:") else line
            for line in status.splitlines()
        ]
        (doomed / "status").write_text("\n".join(lines) + "\n")
        assert _dying(doomed, me), key
    exiting = [*me[:6], str(int(me[6]) | 0x4), *me[7:]]
    assert _dying(Path(f"/proc/{os.getpid()}"), exiting)
