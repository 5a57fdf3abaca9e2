"""Drive Debian's headless Chromium from tests: the DOM after scripts ran, console, screenshot,
and real mouse input.

One way for the whole project (the fleet dashboard's test started it): run the `chromium`
binary with a throw-away profile and no network services. `render` (`--dump-dom`) gives
the page as the browser left it, with the browser's console on stderr (`:CONSOLE` lines);
`screenshot` (`--screenshot`) a PNG kept as a test artifact. `Session` keeps a page open
and talks the DevTools protocol to it over `--remote-debugging-pipe` (JSON messages ended
by a NUL byte on file descriptors 3 and 4, no port, no extra library): evaluate script,
and dispatch mouse events the way a user's mouse makes them (`Input.dispatchMouseEvent`).
"""

from __future__ import annotations

import base64
import contextlib
import fcntl
import json
import os
import select
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

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
    made = _private(shot)
    _run([f"--screenshot={made}", f"--window-size={width},{height}", page.resolve().as_uri()])
    os.replace(made, shot)
    return shot


def _private(shot: Path) -> Path:
    """A name beside `shot` no other test run uses: the artifacts folder is shared by every
    pytest on the machine, and a file is only ever replaced whole (never seen half written)."""
    return shot.with_name(f".{shot.stem}.{os.getpid()}{shot.suffix}")


class BrowserError(RuntimeError):
    """The browser answered a DevTools command with an error, or not at all."""


@dataclass(slots=True)
class Session:
    """A page in headless Chromium driven over the DevTools protocol (a pipe, no port).

    Use as a context manager: `with Session() as s: s.open(page); s.evaluate("1 + 1")`.
    `console` collects the page's console messages and uncaught exceptions.
    """

    width: int = 1100
    height: int = 900
    timeout_s: float = 60.0
    console: list[str] = field(default_factory=list)
    _process: subprocess.Popen[bytes] | None = None
    _profile: tempfile.TemporaryDirectory[str] | None = None
    _to_browser: int = -1
    _from_browser: int = -1
    _buffer: bytes = b""
    _next_id: int = 0
    _session_id: str = ""
    _events: list[dict[str, Any]] = field(default_factory=list)

    def __enter__(self) -> Session:
        assert CHROMIUM is not None
        self._profile = tempfile.TemporaryDirectory()
        commands_r, commands_w = os.pipe()
        replies_r, replies_w = os.pipe()
        # Above 10 so that placing them on 3 and 4 in the child cannot overwrite each other.
        child_in = fcntl.fcntl(commands_r, fcntl.F_DUPFD, 10)
        child_out = fcntl.fcntl(replies_w, fcntl.F_DUPFD, 10)
        os.close(commands_r)
        os.close(replies_w)

        def place_pipes() -> None:  # runs in the child between fork and exec
            os.dup2(child_in, 3)
            os.dup2(child_out, 4)

        self._process = subprocess.Popen(
            [
                CHROMIUM,
                *CHROMIUM_FLAGS,
                f"--user-data-dir={self._profile.name}",
                "--remote-debugging-pipe",
                f"--window-size={self.width},{self.height}",
                "about:blank",
            ],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            pass_fds=(3, 4),
            preexec_fn=place_pipes,
        )
        os.close(child_in)
        os.close(child_out)
        self._to_browser, self._from_browser = commands_w, replies_r
        target = self._call("Target.createTarget", {"url": "about:blank"})["targetId"]
        attached = self._call("Target.attachToTarget", {"targetId": target, "flatten": True})
        self._session_id = attached["sessionId"]
        for domain in ("Page", "Runtime", "Log"):
            self.call(f"{domain}.enable")
        self.call(
            "Emulation.setDeviceMetricsOverride",
            {"width": self.width, "height": self.height, "deviceScaleFactor": 1, "mobile": False},
        )
        return self

    def __exit__(self, *exc: object) -> None:
        if self._process is not None:
            with contextlib.suppress(BrowserError, OSError):
                self._call("Browser.close", timeout_s=5.0)
            try:
                self._process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.wait()
        for fd in (self._to_browser, self._from_browser):
            if fd >= 0:
                os.close(fd)
        self._to_browser = self._from_browser = -1
        if self._profile is not None:
            self._profile.cleanup()

    # -- protocol ---------------------------------------------------------------------
    def _send(self, message: dict[str, Any]) -> None:
        os.write(self._to_browser, json.dumps(message).encode() + b"\0")

    def _receive(self, deadline: float) -> dict[str, Any]:
        while b"\0" not in self._buffer:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self._from_browser], [], [], left)[0]:
                raise BrowserError("no answer from chromium in time")
            chunk = os.read(self._from_browser, 1 << 20)
            if not chunk:
                raise BrowserError("chromium closed the DevTools pipe")
            self._buffer += chunk
        message, _, self._buffer = self._buffer.partition(b"\0")
        parsed: dict[str, Any] = json.loads(message)
        return parsed

    def _call(
        self,
        method: str,
        params: dict[str, Any] | None = None,
        *,
        session: str = "",
        timeout_s: float | None = None,
    ) -> dict[str, Any]:
        self._next_id += 1
        message: dict[str, Any] = {"id": self._next_id, "method": method, "params": params or {}}
        if session:
            message["sessionId"] = session
        self._send(message)
        deadline = time.monotonic() + (timeout_s or self.timeout_s)
        while True:
            reply = self._receive(deadline)
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise BrowserError(f"{method}: {reply['error']}")
                result: dict[str, Any] = reply.get("result", {})
                return result
            self._event(reply)

    def _event(self, event: dict[str, Any]) -> None:
        self._events.append(event)
        method, params = event.get("method"), event.get("params", {})
        if method == "Runtime.consoleAPICalled":
            text = " ".join(str(a.get("value", a.get("description", ""))) for a in params["args"])
            self.console.append(f"console.{params['type']}: {text}")
        elif method == "Runtime.exceptionThrown":
            details = params["exceptionDetails"]
            thrown = details.get("exception", {}).get("description", details.get("text", ""))
            self.console.append(f"exception: {thrown}")
        elif method == "Log.entryAdded":
            entry = params["entry"]
            self.console.append(f"log.{entry['level']}: {entry['text']}")

    def call(self, method: str, params: dict[str, Any] | None = None) -> dict[str, Any]:
        """Send one DevTools command to the page; its result."""
        return self._call(method, params, session=self._session_id)

    def _wait_for(self, method: str) -> None:
        deadline = time.monotonic() + self.timeout_s
        while not any(e.get("method") == method for e in self._events):
            self._event(self._receive(deadline))

    # -- what a test does -------------------------------------------------------------
    def open(self, page: Path, *, fragment: str = "") -> None:
        """Load a local page (with `#fragment`) and wait for its load event."""
        self._events.clear()
        url = page.resolve().as_uri() + (f"#{fragment}" if fragment else "")
        self.call("Page.navigate", {"url": url})
        self._wait_for("Page.loadEventFired")

    def evaluate(self, expression: str) -> Any:
        """The value of a script expression in the page (JSON-serialisable results)."""
        reply = self.call(
            "Runtime.evaluate",
            {"expression": expression, "returnByValue": True, "awaitPromise": True},
        )
        if "exceptionDetails" in reply:
            raise BrowserError(f"{expression!r}: {reply['exceptionDetails']}")
        return reply["result"].get("value")

    def mouse(
        self, kind: str, x: float, y: float, *, pressed: bool = False, clicks: int = 1
    ) -> None:
        """One mouse event at viewport (CSS pixel) x, y: 'mouseMoved', 'mousePressed' or
        'mouseReleased'; `pressed` moves with the left button held."""
        params: dict[str, Any] = {"type": kind, "x": x, "y": y}
        if kind != "mouseMoved":
            params.update(
                button="left", clickCount=clicks, buttons=1 if kind == "mousePressed" else 0
            )
        elif pressed:
            params.update(button="left", buttons=1)
        self.call("Input.dispatchMouseEvent", params)

    def drag(self, start: tuple[float, float], end: tuple[float, float], *, steps: int = 8) -> None:
        """Press the left button at `start`, move in `steps` to `end`, release there."""
        self.mouse("mouseMoved", *start)
        self.mouse("mousePressed", *start)
        for i in range(1, steps + 1):
            f = i / steps
            point = (start[0] + (end[0] - start[0]) * f, start[1] + (end[1] - start[1]) * f)
            self.mouse("mouseMoved", *point, pressed=True)
        self.mouse("mouseReleased", *end)

    def double_click(self, x: float, y: float) -> None:
        """Two clicks in a row at x, y (the second one a double-click)."""
        self.mouse("mouseMoved", x, y)
        for clicks in (1, 2):
            self.mouse("mousePressed", x, y, clicks=clicks)
            self.mouse("mouseReleased", x, y, clicks=clicks)

    def screenshot(self, name: str) -> Path:
        """A PNG of the viewport kept under the artifacts folder; returns its path."""
        shot = ARTIFACTS / name
        shot.parent.mkdir(parents=True, exist_ok=True)
        data = self.call("Page.captureScreenshot", {"format": "png"})["data"]
        made = _private(shot)
        made.write_bytes(base64.b64decode(data))
        os.replace(made, shot)
        return shot
