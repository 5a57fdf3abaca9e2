"""Gate progress: a rich bar with per-log status on a terminal, one line per log otherwise.

The terminal case runs the real command line under a pseudo-terminal (stdlib `pty`), so
`sys.stderr.isatty()` is true in the gate process as it is for a person at a terminal.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import pty
import re
import struct
import subprocess
import sys
import termios
from pathlib import Path

import pytest

from .test_gate import POLICY

ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]|\x1b\][^\x07]*\x07")
REDRAW = re.compile(r"\r|\x1b\[2K")
"""Carriage return and erase-line: where the live display starts drawing a line again."""


def _screen_lines(raw: str) -> str:
    """What was drawn, one drawn line per text line (redraws on lines of their own)."""
    return ANSI.sub("", REDRAW.sub("\n", raw))


WIDTH = 160


def _argv(tmp_path: Path) -> list[str]:
    policy = tmp_path / "policy.json"
    policy.write_text(json.dumps(POLICY))
    return [
        sys.executable,
        "-m",
        "syncaudit.cli",
        "gate",
        "uploads",
        "--policy",
        str(policy),
        "--no-db",
        "--jobs",
        "1",
    ]


def _run_in_pty(argv: list[str], cwd: Path) -> tuple[int, str]:
    """Run `argv` with stdin/stdout/stderr on a pseudo-terminal WIDTH columns wide."""
    env = {**os.environ, "TERM": "xterm-256color", "COLUMNS": str(WIDTH), "LINES": "40"}
    env.pop("NO_COLOR", None)
    pid, fd = pty.fork()
    if pid == 0:  # the child: its terminal is the pty's slave side
        try:
            fcntl.ioctl(0, termios.TIOCSWINSZ, struct.pack("HHHH", 40, WIDTH, 0, 0))
            os.chdir(cwd)
            os.execve(argv[0], argv, env)
        finally:
            os._exit(127)
    chunks = []
    while True:
        try:
            data = os.read(fd, 65536)
        except OSError as exc:  # EIO: the child closed the terminal
            if exc.errno != errno.EIO:
                raise
            break
        if not data:
            break
        chunks.append(data)
    os.close(fd)
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status), b"".join(chunks).decode("utf-8", "replace")


@pytest.mark.skipif(not hasattr(pty, "fork"), reason="needs a POSIX pseudo-terminal")
def test_a_terminal_gets_the_rich_bar_with_per_log_status(
    small_fleet: Path, tmp_path: Path
) -> None:
    code, raw = _run_in_pty(_argv(tmp_path), small_fleet.parent)
    assert code == 10, raw
    assert "\x1b[" in raw  # styled and redrawn: a live display, not plain lines
    screen = _screen_lines(raw)
    car1 = "uploads/car1/vlp16_three_cameras.mcap"
    car2 = "uploads/car2/pandar40p_adaptive.mcap"
    # Per-log status above the bar for every log that did not pass ...
    assert re.search(rf"^fail\s+{re.escape(car1)}\s*$", screen, re.M), screen
    assert re.search(rf"^warn\s+{re.escape(car2)}\s*$", screen, re.M), screen
    # ... and the bar itself: done/total and the last log's verdict and path.
    assert re.search(rf"gate .*2/2 .*warn: {re.escape(car2)}", screen), screen
    assert re.search(r"gate .*1/2 .*fail: uploads/car1/", screen), screen
    assert "[1/2]" not in screen  # not the line-oriented progress
    assert "gate: 2 log(s): 0 pass, 1 warn, 1 fail, 0 error" in screen


def test_a_pipe_gets_one_plain_line_per_log(small_fleet: Path, tmp_path: Path) -> None:
    done = subprocess.run(
        _argv(tmp_path),
        cwd=small_fleet.parent,
        capture_output=True,
        text=True,
        timeout=120,
        env={k: v for k, v in os.environ.items() if k not in ("FORCE_COLOR", "TTY_COMPATIBLE")},
    )
    assert done.returncode == 10, done.stderr
    assert "\x1b" not in done.stderr
    lines = done.stderr.splitlines()
    assert lines[:2] == [
        "[1/2] fail uploads/car1/vlp16_three_cameras.mcap",
        "[2/2] warn uploads/car2/pandar40p_adaptive.mcap",
    ]
    assert lines[-1] == "gate: 2 log(s): 0 pass, 1 warn, 1 fail, 0 error"


def test_the_bar_is_drawn_with_each_logs_state_before_its_status_line(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Each log's count is drawn when it ends, not at the next tick of the bar's refresh
    thread: with no refresh thread at all (a loaded machine starves it), the bar redrawn
    under each status line shows that log's count (it showed 0/? on CI-like load)."""
    import io
    from types import SimpleNamespace

    import rich.progress
    from rich.console import Console

    from syncaudit.cli import fleet_commands as fleet_cli

    out = io.StringIO()
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    monkeypatch.setattr(
        fleet_cli,
        "stderr_console",
        lambda: Console(file=out, force_terminal=True, width=WIDTH, soft_wrap=True),
    )
    original = rich.progress.Progress.__init__

    def no_refresh_thread(self: rich.progress.Progress, *args: object, **kwargs: object) -> None:
        original(self, *args, **{**kwargs, "auto_refresh": False})  # type: ignore[arg-type]

    monkeypatch.setattr(rich.progress.Progress, "__init__", no_refresh_thread)
    update, finish = fleet_cli._progress_printer()
    update(SimpleNamespace(verdict="fail", path="uploads/car1/a.mcap", error=""), 1, 2)
    update(SimpleNamespace(verdict="warn", path="uploads/car2/b.mcap", error=""), 2, 2)
    finish()
    screen = _screen_lines(out.getvalue())
    assert re.search(r"gate .*1/2 .*fail: uploads/car1/a\.mcap", screen), screen
    assert re.search(r"gate .*2/2 .*warn: uploads/car2/b\.mcap", screen), screen
