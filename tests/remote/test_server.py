"""The tests' Range server ends with its test and answers a client that hangs up quietly.

CI once printed socketserver's "Exception occurred during processing of request" in the
middle of later tests: the slow-server test's handler was still sleeping out its delay
(a daemon thread the server did not join), then wrote its reply to the client that had
timed out long before (BrokenPipeError).
"""

from __future__ import annotations

import socket
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path
from urllib.parse import urlsplit

import pytest

from .conftest import _server


def _handlers() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if "process_request_thread" in t.name]


def test_a_handler_waiting_out_its_delay_ends_with_the_test(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    before = _handlers()
    served = _server(tmp_path / "www")
    try:
        base, state = next(served)
        (state.root / "slow.bin").write_bytes(bytes(1000))
        state.delay_s = 600
        with pytest.raises((TimeoutError, urllib.error.URLError)):
            urllib.request.urlopen(f"{base}/slow.bin", timeout=0.5)  # the client gives up
        deadline = time.monotonic() + 60
        while len(_handlers()) == len(before) and time.monotonic() < deadline:
            time.sleep(0.01)  # (the handler thread exists once the server accepted)
        assert len(_handlers()) == len(before) + 1, "the server never took the request"
        began = time.monotonic()
        with pytest.raises(StopIteration):
            next(served)  # the fixture's teardown
    finally:
        served.close()  # (after a failed assertion: the teardown still runs)
    assert time.monotonic() - began < 60  # woken, not the 600 s delay
    assert _handlers() == before  # joined: nothing of this test answers later
    assert state.errors == []
    assert "Exception occurred" not in capfd.readouterr().err


def test_a_client_hanging_up_mid_reply_is_counted_not_printed(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    served = _server(tmp_path / "www")
    try:
        base, state = next(served)
        (state.root / "big.bin").write_bytes(bytes(64 << 20))  # more than socket buffers hold
        address = urlsplit(base)
        with socket.create_connection((address.hostname, address.port), timeout=60) as client:
            client.sendall(b"GET /big.bin HTTP/1.0\r\nHost: x\r\n\r\n")
            assert client.recv(4096).startswith(b"HTTP/1.0 200")
        # Closed with unread data: the kernel resets the connection; the handler's next
        # write fails as a real server's does when a reader stops early.
        with pytest.raises(StopIteration):
            next(served)
    finally:
        served.close()
    assert state.hangups == 1
    assert state.errors == []
    err = capfd.readouterr().err
    assert "Exception occurred" not in err and "BrokenPipe" not in err, err
