"""The README's set-up commands run as written, on a clean clone in a fresh venv.

Slow (3.5 min on the loaded 2-core machine: a clone, a venv, two installs): marked
`slow`, so `pytest -m "not slow"` leaves it out; CI's `pytest` runs it. To stay bounded it runs command 2's install
part as written but its `pytest` part as `pytest -m "not slow" -x -q tests/cli` (the
whole suite already runs in CI's own `pytest`); everything else is taken literally from
the README, so the README cannot drift from the code.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SETUP = "## Set-up in two commands"


def readme_commands(text: str) -> list[str]:
    """The shell blocks of the README's set-up section, in order."""
    section = text.split(SETUP, 1)[1].split("\n## ", 1)[0]
    return [block.strip() for block in re.findall(r"```sh\n(.*?)```", section, re.S)]


def test_readme_has_two_setup_commands_and_ci_runs_the_second() -> None:
    commands = readme_commands((REPO / "README.md").read_text())
    assert len(commands) == 2
    # The command itself, on a line of its own that runs (not in a comment or an echo).
    lines = [line.strip() for line in (REPO / ".ci" / "run").read_text().splitlines()]
    assert commands[1] in lines
    assert not any(commands[1] in line for line in lines if line.startswith("#"))


def test_readme_exit_code_table_is_the_one_in_errors() -> None:
    from syncaudit.errors import exit_code_table

    assert exit_code_table() in (REPO / "README.md").read_text()


@pytest.mark.slow
@pytest.mark.timeout(2 * 900 + 600)  # two commands of at most 900 s each, clone and venv
def test_readme_commands_run_on_a_clean_clone(tmp_path: Path) -> None:
    if shutil.which("git") is None or not (REPO / ".git").exists():
        pytest.skip("needs git and a git checkout")
    first, second = readme_commands((REPO / "README.md").read_text())
    clone = tmp_path / "syncaudit"
    subprocess.run(["git", "clone", "-q", str(REPO), str(clone)], check=True)
    head = subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True, check=True
    ).stdout.strip()
    subprocess.run(["git", "-C", str(clone), "checkout", "-q", head], check=True)
    shared = REPO.parent / "shared"
    if shared.is_dir():  # the tests find the real recordings beside the checkout
        (tmp_path / "shared").symlink_to(shared)
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    env = {**os.environ, "PATH": f"{venv / 'bin'}:{os.environ['PATH']}", "VIRTUAL_ENV": str(venv)}
    env.pop("PYTHONPATH", None)

    def shell(command: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            ["bash", "-c", command],
            cwd=clone,
            env=env,
            capture_output=True,
            text=True,
            check=False,
            timeout=900,
        )

    ran = shell(first)
    assert ran.returncode == 0, ran.stdout[-2000:] + ran.stderr[-2000:]
    assert "verdict" in ran.stdout
    install, _, test = second.partition(" && ")
    assert test.strip() == "pytest"
    ran = shell(f'{install} && pytest -m "not slow" -x -q tests/cli -p no:cacheprovider')
    assert ran.returncode == 0, ran.stdout[-3000:] + ran.stderr[-2000:]
