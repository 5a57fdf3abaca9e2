"""The README's exit codes, whatever happens to stdout and stderr, in real subprocesses.

A missing input is 2 (cannot be opened), a missing extra 64 (usage error), a closed pipe or a
full stderr never changes the code, a full stdout turns only a success into 8. The streams
are real pipes, /dev/full and closed descriptors, as a shell gives them.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from hostile_configs import alias_bomb

SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"
MCAP = SAMPLES / "vlp16_three_cameras.mcap"
BAG = SAMPLES / "vlp16_short.bag"
TIMEOUT_S = 120

GATE_FAILED = 10  # the sample's sync audit fails its default thresholds
NEEDS_DEV_FULL = pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full")


def _cli(*args: str | Path) -> list[str]:
    return [sys.executable, "-m", "syncaudit", *(str(a) for a in args)]


def _shell(redirect: str, *args: str | Path, env: dict[str, str] | None = None) -> int:
    """The command's exit code with its streams redirected as in `sh -c 'cmd REDIRECT'`."""
    line = " ".join(f"'{part}'" for part in _cli(*args)) + " " + redirect
    done = subprocess.run(
        ["sh", "-c", line], env=env, timeout=TIMEOUT_S, check=False, capture_output=True
    )
    return done.returncode


def _closed_pipe(*args: str | Path) -> int:
    """The exit code when stdout and stderr are one pipe its reader closed at once."""
    read_fd, write_fd = os.pipe()
    os.close(read_fd)  # the reader went away before the first line (`2>&1 | true`)
    try:
        proc = subprocess.Popen(_cli(*args), stdout=write_fd, stderr=write_fd)
    finally:
        os.close(write_fd)
    return proc.wait(timeout=TIMEOUT_S)


def _run(*args: str | Path, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        _cli(*args), capture_output=True, text=True, env=env, timeout=TIMEOUT_S, check=False
    )


def _hiding(tmp_path: Path, module: str) -> dict[str, str]:
    """An environment where importing `module` fails, as without its extra installed."""
    fake = tmp_path / "hide" / module
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text(f"raise ImportError('{module} hidden by the test')\n")
    return {**os.environ, "PYTHONPATH": str(tmp_path / "hide")}


@pytest.mark.parametrize("command", ["audit", "info"])
def test_missing_rig_cannot_be_opened(tmp_path: Path, command: str) -> None:
    done = _run(command, MCAP, "--rig", tmp_path / "missing.yaml")
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and "missing.yaml" in done.stderr


def test_missing_results_database_cannot_be_opened(tmp_path: Path) -> None:
    done = _run("fleet", "report", "--db", tmp_path / "missing.duckdb", "--html", tmp_path / "o")
    assert done.returncode == 2, done.stderr
    assert "missing.duckdb" in done.stderr
    assert not (tmp_path / "o").exists()


def test_parquet_without_pyarrow_is_a_usage_error(tmp_path: Path) -> None:
    out = tmp_path / "f.parquet"
    # --no-rig: the note that the rig beside the log is used would be a second line.
    done = _run("audit", MCAP, "--no-rig", "--parquet", out, env=_hiding(tmp_path, "pyarrow"))
    assert done.returncode == 64, done.stderr
    assert "syncaudit[parquet]" in done.stderr and done.stderr.count("\n") == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hide"]


@pytest.mark.parametrize("module", ["small_gicp", "gtsam"])
def test_calib_without_its_extra_is_a_usage_error(tmp_path: Path, module: str) -> None:
    done = _run("calib", BAG, env=_hiding(tmp_path, module))
    assert done.returncode == 64, done.stderr
    assert "syncaudit[calib]" in done.stderr and module in done.stderr


@pytest.mark.parametrize(
    ("args", "code"),
    [
        (("audit", MCAP, "--gate"), GATE_FAILED),
        (("audit", MCAP, "--gate", "--json"), GATE_FAILED),
        (("audit", MCAP), 0),
        (("info", MCAP, "--json"), 0),
        (("audit", MCAP, "--rig", "/nonexistent/rig.yaml"), 2),
        (("audit", MCAP, "--no-such-option"), 64),
        (("--help",), 0),
    ],
)
def test_closed_pipe_keeps_the_exit_code(args: tuple[str | Path, ...], code: int) -> None:
    assert _closed_pipe(*args) == code


def test_closed_pipe_keeps_a_hostile_rig_refusal(tmp_path: Path) -> None:
    rig = tmp_path / "bomb.yaml"
    rig.write_bytes(alias_bomb())
    assert _closed_pipe("audit", MCAP, "--rig", rig) == 6


@NEEDS_DEV_FULL
@pytest.mark.parametrize(
    ("redirect", "args", "code"),
    [
        ("2>/dev/full >/dev/null", ("audit", MCAP, "--gate"), GATE_FAILED),
        ("2>/dev/full", ("audit", MCAP, "--rig", "/nonexistent/rig.yaml"), 2),
        ("2>/dev/full", ("audit", MCAP, "--no-such-option"), 64),
        (">/dev/full 2>/dev/null", ("audit", MCAP, "--gate"), GATE_FAILED),
        (">/dev/full 2>/dev/full", ("audit", MCAP, "--gate"), GATE_FAILED),
        (">/dev/full 2>/dev/null", ("audit", MCAP), 8),
        (">/dev/full 2>/dev/null", ("info", MCAP, "--json"), 8),
        (">/dev/full 2>/dev/null", ("audit", "--help"), 8),
    ],
)
def test_full_disk_on_a_stream(redirect: str, args: tuple[str | Path, ...], code: int) -> None:
    assert _shell(redirect, *args) == code


def test_full_stdout_says_so_on_stderr() -> None:
    line = " ".join(f"'{part}'" for part in _cli("audit", MCAP, "--no-rig")) + " >/dev/full"
    done = subprocess.run(["sh", "-c", line], capture_output=True, text=True, check=False)
    assert done.returncode == 8
    assert done.stderr.strip().splitlines() == [
        "error: stdout: No space left on device (the result was not written)"
    ]


@pytest.mark.parametrize(
    ("redirect", "code"), [(">&-", 0), ("2>&- >&-", GATE_FAILED), ("<&- >&- 2>&-", GATE_FAILED)]
)
def test_closed_descriptors_keep_the_exit_code(tmp_path: Path, redirect: str, code: int) -> None:
    args: tuple[str | Path, ...] = ("audit", MCAP, "--json-out", tmp_path / "a.json")
    if code == GATE_FAILED:
        args = (*args, "--gate")
    assert _shell(redirect, *args) == code
    text = (tmp_path / "a.json").read_text()
    assert text.startswith("{") and "error:" not in text  # no line went into the output file
