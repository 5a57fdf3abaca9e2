"""A real HTTP server on loopback that honours Range requests (and can misbehave), and
moto's S3 server on loopback with two sample logs (`s3_endpoint`).

Each test's server is its own and ends with the test: the fixture wakes any handler still
waiting (`delay_s`), stops the server and joins every handler thread, so no request of an
earlier test is still being answered while later tests run. A client that hangs up before
the reply is complete (a reader that timed out, a ranged reader that has what it needs) is
counted in `hangups` quietly; any other error in a handler fails the test at teardown
instead of being printed by socketserver in the middle of other tests' output.
"""

from __future__ import annotations

import re
import sys
import threading
import traceback
from collections.abc import Iterator
from dataclasses import dataclass, field
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import pytest

from syncaudit.logs import LogReader


def fetched(log: LogReader) -> dict[str, Any]:
    """What reading a remote log has fetched so far (its `remote_read`), as a dict."""
    stats = log.fetch_stats
    assert stats is not None, f"{log.summary.path} is not a remote log"
    return stats.to_dict()


RANGE = re.compile(r"bytes=(\d+)-(\d*)$")
SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"
SECRET = "not-a-real-secret-0123456789"
"""The S3 server's secret key: it must appear in nothing syncaudit writes."""


@dataclass
class ServerState:
    """What the handler does, and what it served (for the tests' byte counts)."""

    root: Path
    drop_after_bytes: int | None = None
    """Close the connection after sending this many body bytes of a ranged reply."""
    drop_min_length: int = 1 << 16
    """Only replies at least this long are dropped (the small footer read goes through)."""
    drops_left: int | None = None
    """Drop only this many replies (None: every one that qualifies)."""
    ignore_range: bool = False
    """Answer every GET with the whole file (200), as a server without Range support."""
    delay_s: float = 0.0
    redirects: dict[str, tuple[int, str]] = field(default_factory=dict)
    """Request path (query string included) -> (status, Location) answered instead."""
    authorizations: list[tuple[str, str | None]] = field(default_factory=list)
    """(path, Authorization header) of every GET."""
    required_query: str | None = None
    """Refuse (403) a GET of a file whose query string is not this (a signed URL's)."""
    served_bytes: int = 0
    requests: list[str] = field(default_factory=list)
    ranged_bytes: int = 0
    """Bytes asked for by the Range headers of 206 replies."""
    lock: threading.Lock = field(default_factory=threading.Lock)
    stop: threading.Event = field(default_factory=threading.Event)
    """Set when the test ends: a handler waiting out `delay_s` returns without replying."""
    hangups: int = 0
    """Replies cut short because the client closed its connection first."""
    errors: list[str] = field(default_factory=list)
    """Tracebacks of any other exception raised while handling a request."""


HANGUPS = (BrokenPipeError, ConnectionResetError, ConnectionAbortedError)
"""What writing to a connection the client has closed raises."""
HANDLER_TIMEOUT_S = 60.0
"""Socket timeout of a handler's connection: bounds the teardown's join of a handler whose
client neither reads nor closes (never reached by a working client, even on a loaded
machine)."""


class RangeServer(ThreadingHTTPServer):
    """A threaded HTTP server whose handler threads are joined when it closes, and whose
    handler errors go to the test's `ServerState` instead of stderr."""

    daemon_threads = False  # tracked, so that server_close() joins them
    block_on_close = True
    state: ServerState

    def handle_error(self, request: Any, client_address: Any) -> None:
        """A client that hung up is counted; anything else is kept for the teardown."""
        error = sys.exc_info()[1]
        with self.state.lock:
            if isinstance(error, HANGUPS):
                self.state.hangups += 1
            else:
                self.state.errors.append(f"request from {client_address}: {traceback.format_exc()}")


class RangeHandler(SimpleHTTPRequestHandler):
    """Static files with single-range `Range: bytes=a-b` support (RFC 9110 206 replies)."""

    state: ServerState
    disable_nagle_algorithm = True  # TCP_NODELAY, as real servers (nginx, aiohttp) set it
    timeout = HANDLER_TIMEOUT_S

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, directory=str(self.state.root), **kwargs)

    def log_message(self, format: str, *args: Any) -> None:
        """Quiet."""

    def do_GET(self) -> None:
        state = self.state
        with state.lock:
            state.requests.append(f"{self.path} {self.headers.get('Range')}")
            state.authorizations.append((self.path, self.headers.get("Authorization")))
        redirect = state.redirects.get(self.path)
        if redirect is not None:
            self.send_response(redirect[0])
            self.send_header("Location", redirect[1])
            self.send_header("Content-Length", "0")
            self.end_headers()
            return
        if state.delay_s and state.stop.wait(state.delay_s):
            self.close_connection = True  # the test is over: no reply to a gone client
            return
        path = Path(self.translate_path(self.path))
        if path.is_dir() or not path.is_file():
            super().do_GET()
            return
        query = self.path.partition("?")[2]
        if state.required_query is not None and query != state.required_query:
            self.send_error(403, "signature does not match")
            return
        size = path.stat().st_size
        match = RANGE.match(self.headers.get("Range", "") or "")
        if state.ignore_range:
            match = None
        if not match:
            start, end = 0, size
            self.send_response(200)
        else:
            start = int(match.group(1))
            end = min(size, int(match.group(2)) + 1) if match.group(2) else size
            if start >= size:
                self.send_response(416)
                self.send_header("Content-Range", f"bytes */{size}")
                self.end_headers()
                return
            with state.lock:
                state.ranged_bytes += end - start
            self.send_response(206)
            self.send_header("Content-Range", f"bytes {start}-{end - 1}/{size}")
        self.send_header("Content-Length", str(end - start))
        self.send_header("Accept-Ranges", "bytes")
        self.send_header("Content-Type", "application/octet-stream")
        self.end_headers()
        length = end - start
        drop = state.drop_after_bytes if length >= state.drop_min_length and match else None
        if drop is not None and state.drops_left is not None:
            with state.lock:
                if state.drops_left > 0:
                    state.drops_left -= 1
                else:
                    drop = None
        with path.open("rb") as handle:
            handle.seek(start)
            sent = 0
            while sent < length:
                block = handle.read(min(1 << 20, length - sent))
                if drop is not None:
                    block = block[: max(0, drop - sent)]
                    self.wfile.write(block)
                    sent += len(block)
                    with state.lock:
                        state.served_bytes += len(block)
                    self.wfile.flush()
                    self.close_connection = True
                    self.connection.shutdown(2)  # mid-chunk: the client sees a short body
                    return
                self.wfile.write(block)
                sent += len(block)
                with state.lock:
                    state.served_bytes += len(block)

    def do_HEAD(self) -> None:
        path = Path(self.translate_path(self.path))
        if not path.is_file():
            super().do_HEAD()
            return
        self.send_response(200)
        self.send_header("Content-Length", str(path.stat().st_size))
        self.send_header("Accept-Ranges", "bytes")
        self.end_headers()


@pytest.fixture()
def http_root(tmp_path: Path) -> Iterator[tuple[str, ServerState]]:
    """(base URL, state) of a threaded Range server over a fresh folder, on 127.0.0.1."""
    yield from _server(tmp_path / "www")


@pytest.fixture()
def other_http_root(tmp_path: Path) -> Iterator[tuple[str, ServerState]]:
    """A second server (another port: another origin), for redirects across hosts."""
    yield from _server(tmp_path / "www-other")


def _server(root: Path) -> Iterator[tuple[str, ServerState]]:
    root.mkdir()
    state = ServerState(root)
    handler = type("Handler", (RangeHandler,), {"state": state})
    server = RangeServer(("127.0.0.1", 0), handler)
    server.state = state
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}", state
    finally:
        state.stop.set()
        server.shutdown()
        server.server_close()  # joins every handler thread
        thread.join()
    assert not state.errors, "the test server failed a request:\n" + "\n".join(state.errors)


@pytest.fixture()
def s3_endpoint(monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    """moto's S3 server on 127.0.0.1 with a bucket holding two sample logs."""
    moto_server = pytest.importorskip("moto.server")
    s3fs = pytest.importorskip("s3fs")
    boto3 = pytest.importorskip("boto3")
    server = moto_server.ThreadedMotoServer(ip_address="127.0.0.1", port=0, verbose=False)
    server.start()
    host, port = server.get_host_and_port()
    endpoint = f"http://{host}:{port}"
    monkeypatch.setenv("AWS_ACCESS_KEY_ID", "testing")
    monkeypatch.setenv("AWS_SECRET_ACCESS_KEY", SECRET)
    monkeypatch.setenv("AWS_DEFAULT_REGION", "us-east-1")
    monkeypatch.setenv("AWS_ENDPOINT_URL", endpoint)
    # fsspec caches filesystems by their arguments: one made for an earlier test's server
    # (same environment-given arguments, another port) must not be reused.
    s3fs.S3FileSystem.clear_instance_cache()
    try:
        client = boto3.client("s3", endpoint_url=endpoint)
        client.create_bucket(Bucket="fleet")
        for key, name in (
            ("uploads/car1/a.mcap", "vlp16_three_cameras.mcap"),
            ("uploads/car2/b.bag", "vlp16_short.bag"),
        ):
            client.upload_file(str(SAMPLES / name), "fleet", key)
        yield endpoint
    finally:
        server.stop()
