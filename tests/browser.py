"""Drive Debian's headless Chromium from tests: the DOM after scripts ran, console, screenshot.

One way for the whole project (the fleet dashboard's test started it): run the `chromium`
binary with a throw-away profile and no network services, `--dump-dom` for the page as
the browser left it (with the browser's console on stderr, `:CONSOLE` lines), and
`--screenshot` for a PNG kept as a test artifact.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

ARTIFACTS = Path(tempfile.gettempdir()) / "syncaudit-test-artifacts"
CHROMIUM = shutil.which("chromium")
CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]

needs_chromium = pytest.mark.skipif(
    CHROMIUM is None,
    reason="chromium is not installed (.ci/run installs Debian's chromium package as root; "
    "without apt-get here the browser checks cannot run)",
)


@dataclass(frozen=True, slots=True)
class Rendered:
    """What the browser made of a page."""

    dom: str
    """The serialised DOM after the page's scripts ran."""
    console: list[str]
    """Console messages (errors, warnings, logs) the page produced."""
    seconds: float
    """Wall time of the --dump-dom run (browser start included)."""


def _run(args: list[str]) -> subprocess.CompletedProcess[str]:
    assert CHROMIUM is not None
    with tempfile.TemporaryDirectory() as profile:
        return subprocess.run(
            [CHROMIUM, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", *args],
            capture_output=True,
            text=True,
            timeout=120,
            check=True,
        )


def render(page: Path, *, fragment: str = "") -> Rendered:
    """Load a local page (with `#fragment`); its DOM after scripts and its console messages."""
    start = time.perf_counter()
    url = page.resolve().as_uri() + (f"#{fragment}" if fragment else "")
    done = _run(["--enable-logging=stderr", "--v=0", "--dump-dom", url])
    seconds = time.perf_counter() - start
    console = [line for line in done.stderr.splitlines() if ":CONSOLE" in line]
    return Rendered(done.stdout, console, seconds)


def screenshot(page: Path, name: str, *, width: int = 1100, height: int = 2400) -> Path:
    """A PNG of the page kept under the artifacts folder; returns its path."""
    shot = ARTIFACTS / name
    shot.parent.mkdir(parents=True, exist_ok=True)
    _run([f"--screenshot={shot}", f"--window-size={width},{height}", page.resolve().as_uri()])
    return shot
