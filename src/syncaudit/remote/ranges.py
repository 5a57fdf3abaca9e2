"""Ranged reads of one remote object, streamed into caller buffers, retried, and counted.

HTTP(S) URLs are read with the standard library's `http.client` over one persistent
connection per process and thread (so a forked chunk worker never shares its parent's
socket): each range is one `GET` with `Range: bytes=a-b`, read with `readinto` straight
into the caller's buffer (no intermediate copy; `benchmarks/bench_remote.py --clients`
measured it against urllib3, requests and fsspec). Redirects (301, 302, 303, 307, 308)
are followed, at most `MAX_REDIRECTS` per request, keeping the Range header; user info
in the URL is sent as Basic credentials to its own origin only, never after a redirect
to another host, port or scheme (as curl and requests do). A permanent redirect (301,
308) is remembered for the object's later ranges; a temporary one is asked again each
time. Other stores (s3://, gs://, az://) go through fsspec: each range is one
`cat_file(path, start, end)`.

A failed or dropped read is retried from the byte where it stopped, `TRIES` attempts in
all per range, then a LogReadError (exit 3) names the URL (without query string or user
info) and the range. What every process of an audit fetched is added to a `FetchCounter`
in shared memory, so the parent can report bytes fetched by its forked workers.
"""

from __future__ import annotations

import base64
import http.client
import io
import multiprocessing
import os
import re
import threading
import time
from contextlib import suppress
from dataclasses import asdict, dataclass
from typing import Any, Protocol
from urllib.parse import unquote, urljoin, urlsplit

from syncaudit.errors import LogOpenError, LogReadError
from syncaudit.remote.urls import filesystem, public_url

TRIES = 3
"""Attempts per range before the read is an error (the first and two retries)."""
RETRY_PAUSE_S = 0.2
"""Pause before the second attempt (doubled before the third)."""
TIMEOUT_S = 60.0
"""Socket timeout of one HTTP connect or read."""
HTTP_SCHEMES = ("http", "https")
MAX_REDIRECTS = 5
"""Redirects followed for one request before the read is an error (curl's default is 50,
browsers ~20: a log behind more than a few is a misconfigured server or a loop)."""
REDIRECTS = frozenset({301, 302, 303, 307, 308})
PERMANENT_REDIRECTS = frozenset({301, 308})
_CONTENT_RANGE = re.compile(r"bytes (\d+)-(\d+)/(\d+|\*)$")


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


class _FatalReplyError(Exception):
    """A reply no retry can change (404, 403, a server ignoring Range)."""


class RefusedReplyError(_FatalReplyError):
    """HTTP 401 or 403: the server refuses this object to these credentials (a signed URL
    covers only its own object; S3 answers 403 for a missing key without list rights)."""


class RefusedReadError(LogReadError):
    """A read the store refused (HTTP 401/403, an object store's PermissionError): no
    retry can change it. `reason` is the refusal in a few words."""

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason

    def __reduce__(self) -> tuple[type[RefusedReadError], tuple[str, str]]:
        return type(self), (str(self), self.reason)


class FetchCounter:
    """Bytes and requests fetched for one URL by every process of an audit (shared memory,
    created before the chunk workers fork)."""

    def __init__(self) -> None:
        self._values = multiprocessing.Array("q", 2)

    def add(self, fetched_bytes: int, requests: int = 0) -> None:
        """Count a read."""
        with self._values.get_lock():
            self._values[0] += fetched_bytes
            self._values[1] += requests

    @property
    def fetched_bytes(self) -> int:
        """Bytes received so far."""
        return int(self._values[0])

    @property
    def requests(self) -> int:
        """Ranged requests sent so far."""
        return int(self._values[1])


@dataclass(slots=True)
class FetchStats:
    """What a remote read cost: bytes fetched against the file size and the needed chunks."""

    url: str
    size_bytes: int
    fetched_bytes: int = 0
    requests: int = 0
    needed_chunk_bytes: int = 0
    chunks_fetched: int = 0
    chunks_total: int = 0
    ranged: bool = True
    whole_reason: str = ""
    """Why the log was downloaded whole rather than read by ranges (when `ranged` is false)."""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return asdict(self)


class Body(Protocol):
    """The body of one ranged reply, read in order."""

    def readinto(self, buffer: memoryview) -> int:
        """Fill a prefix of `buffer`; 0 when the body ended (early if bytes are missing)."""
        ...

    def close(self) -> None:
        """Drop the rest of the reply (and, for HTTP, the connection when unread bytes remain)."""
        ...


class RemoteObject(Protocol):
    """One remote file that can be read by byte ranges."""

    name: str
    """The URL as messages show it (no query string, no user info)."""

    def open(self, start: int, end: int) -> tuple[Body, int]:
        """Bytes start..end-1 as a reply body, and the object's size."""
        ...


def open_object(url: str) -> RemoteObject:
    """An HTTP(S) object read with `http.client`, anything else through fsspec."""
    if urlsplit(url).scheme.lower() in HTTP_SCHEMES:
        return HttpObject(url)
    return FsspecObject(url)


# -- HTTP ------------------------------------------------------------------------------


class _Pool(threading.local):
    """Connections of this thread by (scheme, host, port); forgotten after a fork."""

    def __init__(self) -> None:
        self.pid = os.getpid()
        self.connections: dict[tuple[str, str, int], http.client.HTTPConnection] = {}

    def get(self, scheme: str, host: str, port: int) -> http.client.HTTPConnection:
        """This process's and thread's connection to the server (made on first use)."""
        if self.pid != os.getpid():  # a forked child: the parent's sockets are not ours
            self.pid, self.connections = os.getpid(), {}
        key = (scheme, host, port)
        conn = self.connections.get(key)
        if conn is None:
            cls = http.client.HTTPSConnection if scheme == "https" else http.client.HTTPConnection
            conn = self.connections[key] = cls(host, port, timeout=TIMEOUT_S)
        return conn

    def drop(self, scheme: str, host: str, port: int) -> None:
        """Close and forget a connection (after an error or an unread body)."""
        conn = self.connections.pop((scheme, host, port), None)
        if conn is not None:
            conn.close()


_POOL = _Pool()


class _HttpBody:
    """A ranged reply of `http.client`: `readinto` goes straight to the socket."""

    def __init__(self, target: _Target, response: http.client.HTTPResponse) -> None:
        self._target = target
        self._response = response

    def readinto(self, buffer: memoryview) -> int:
        return self._response.readinto(buffer)

    def close(self) -> None:
        if not self._response.isclosed():
            self._response.close()
            _POOL.drop(self._target.scheme, self._target.host, self._target.port)


class _Target:
    """Where an HTTP request goes: scheme, host, port, path with query, and credentials."""

    def __init__(self, url: str, authorization: str | None) -> None:
        parts = urlsplit(url)
        self.scheme = parts.scheme.lower()
        self.host = parts.hostname or ""
        self.port = parts.port or (443 if self.scheme == "https" else 80)
        self.path = (parts.path or "/") + (f"?{parts.query}" if parts.query else "")
        self.authorization = authorization
        self.url = url

    def same_origin(self, other: _Target) -> bool:
        """Same scheme, host and port (credentials may go along)."""
        return (self.scheme, self.host, self.port) == (other.scheme, other.host, other.port)


def _basic_authorization(url: str) -> str | None:
    """The Basic Authorization header of a URL's user info, if it has any."""
    parts = urlsplit(url)
    if parts.username is None:
        return None
    pair = f"{unquote(parts.username)}:{unquote(parts.password or '')}"
    return "Basic " + base64.b64encode(pair.encode()).decode("ascii")


class HttpObject:
    """An object behind an http(s):// URL (signed URLs keep their query string)."""

    def __init__(self, url: str) -> None:
        self.name = public_url(url)
        self._target = _Target(url, _basic_authorization(url))
        self._current = self._target
        """Where ranges are asked: the URL, or where a permanent redirect moved it."""

    def open(self, start: int, end: int) -> tuple[Body, int]:
        """GET bytes start..end-1: a 206 reply whose Content-Range starts at `start`,
        following redirects."""
        target = self._current
        for _ in range(MAX_REDIRECTS + 1):
            response = self._get(target, start, end)
            if response.status not in REDIRECTS:
                break
            location = response.getheader("Location")
            self._finish(target, response)
            if not location:
                raise _FatalReplyError(f"HTTP {response.status} redirect without a Location")
            moved = _Target(urljoin(target.url, location), None)
            if moved.scheme not in HTTP_SCHEMES:
                raise _FatalReplyError(
                    f"HTTP {response.status} redirect to a {moved.scheme or 'relative'}: URL"
                )
            if moved.same_origin(target):  # credentials stay with their own host
                moved.authorization = target.authorization
            if response.status in PERMANENT_REDIRECTS and target is self._current:
                self._current = moved
            target = moved
        else:
            response.close()
            raise _FatalReplyError(
                f"more than {MAX_REDIRECTS} redirects (last to {public_url(target.url)})"
            )
        return self._check(target, response, start)

    def _get(self, target: _Target, start: int, end: int) -> http.client.HTTPResponse:
        """Send one ranged GET on this thread's connection to the target's server."""
        conn = _POOL.get(target.scheme, target.host, target.port)
        headers = {"Range": f"bytes={start}-{end - 1}", "Accept-Encoding": "identity"}
        if target.authorization is not None:
            headers["Authorization"] = target.authorization
        try:
            conn.request("GET", target.path, headers=headers)
            return conn.getresponse()
        except Exception:
            _POOL.drop(target.scheme, target.host, target.port)
            raise

    def _finish(self, target: _Target, response: http.client.HTTPResponse) -> None:
        """Read a short reply (a redirect's) to its end, so the connection can be reused."""
        with suppress(Exception):
            response.read(1 << 16)
        if not response.isclosed() or response.will_close:
            response.close()
            _POOL.drop(target.scheme, target.host, target.port)

    def _check(
        self, target: _Target, response: http.client.HTTPResponse, start: int
    ) -> tuple[Body, int]:
        """The body of a 206 reply starting at `start`; any other reply raised as an error
        (no such object, Range not honoured, server errors to retry)."""
        if response.status != 206:
            body = response.read(1 << 16) if response.status < 500 else b""
            _POOL.drop(target.scheme, target.host, target.port)
            status = f"HTTP {response.status} {response.reason}".strip()
            if response.status in (404, 410):
                raise FileNotFoundError(status)
            if response.status == 200:
                raise _FatalReplyError(f"{status}: the server does not honour Range requests")
            if response.status in (401, 403):
                raise RefusedReplyError(f"{status} {body[:200]!r}")
            if response.status == 416:
                raise _FatalReplyError(f"{status}: range past the end of the object")
            if response.status < 500:
                raise _FatalReplyError(f"{status} {body[:200]!r}")
            raise ConnectionError(status)
        match = _CONTENT_RANGE.match(response.getheader("Content-Range") or "")
        if match is None or int(match.group(1)) != start or match.group(3) == "*":
            response.close()
            _POOL.drop(target.scheme, target.host, target.port)
            raise _FatalReplyError(
                f"unexpected Content-Range {response.getheader('Content-Range')!r}"
            )
        return _HttpBody(target, response), int(match.group(3))


# -- fsspec (s3://, gs://, az://) ------------------------------------------------------


class FsspecObject:
    """An object in a store fsspec reads: each range is one `cat_file`."""

    def __init__(self, url: str) -> None:
        self.name = public_url(url)
        self._fs, self._path = filesystem(url)
        self._size: int | None = None

    @classmethod
    def of(cls, fs: Any, path: str, name: str, size: int | None = None) -> FsspecObject:
        """An object of a filesystem already open (a fetch's), named `name` in messages."""
        obj = cls.__new__(cls)
        obj.name, obj._fs, obj._path, obj._size = name, fs, path, size
        return obj

    def open(self, start: int, end: int) -> tuple[Body, int]:
        """The range fetched whole into memory (the backends read ranges whole anyway)."""
        if self._size is None:
            self._size = int(self._fs.info(self._path).get("size") or 0)
        data = self._fs.cat_file(self._path, start=start, end=min(end, self._size))
        return io.BytesIO(data), self._size


# -- reading ---------------------------------------------------------------------------


class RangeStream:
    """Bytes start..end-1 of an object, read in order into caller buffers.

    A reply that fails or ends early is asked again from the first byte not yet read;
    after `TRIES` failed attempts the read is a LogReadError naming the URL and range.
    """

    def __init__(
        self, obj: RemoteObject, start: int, end: int, counter: FetchCounter | None
    ) -> None:
        self.obj = obj
        self.start, self.end, self.pos = start, end, start
        self.size: int | None = None
        """The object's size, once a reply told it."""
        self._counter = counter
        self._body: Body | None = None
        self._failures = 0
        self._requests = 0
        self._counted = start
        """Bytes before this position (and `_requests`) are in the shared counter."""

    def begin(self) -> int:
        """Send the request (if not yet sent); the object's size."""
        while self._body is None:
            try:
                self._body, self.size = self.obj.open(self.pos, self.end)
            except Exception as exc:
                self._failed(exc)
                continue
            self._requests += 1
        assert self.size is not None
        return self.size

    def readinto(self, buffer: memoryview) -> None:
        """Fill `buffer` exactly with the next bytes of the range."""
        if self.pos + len(buffer) > self.end:
            raise LogReadError(
                f"{self.obj.name}: read of {len(buffer)} bytes at {self.pos} runs past the "
                f"range {self.start}-{self.end}"
            )
        got = 0
        while got < len(buffer):
            self.begin()
            assert self._body is not None
            try:
                n = self._body.readinto(buffer[got:])
                if n <= 0:
                    raise ConnectionError(
                        f"reply ended after {self.pos - self.start} of "
                        f"{self.end - self.start} bytes"
                    )
            except Exception as exc:
                self._failed(exc)
                continue
            got += n
            self.pos += n

    def _failed(self, exc: Exception) -> None:
        """Drop the reply; raise at once for what no retry can change, or after `TRIES`
        failures; else pause before the next attempt."""
        self.close()
        if isinstance(exc, FileNotFoundError):
            raise LogOpenError(f"{self.obj.name}: no such log ({_one_line(exc)})") from None
        if isinstance(exc, RefusedReplyError | PermissionError):
            raise RefusedReadError(
                f"{self.obj.name}: reading bytes {self.start}-{self.end}: {_one_line(exc)}",
                " ".join(_one_line(exc).split()[:3]),
            ) from None
        if isinstance(exc, _FatalReplyError | LogReadError):
            raise LogReadError(
                f"{self.obj.name}: reading bytes {self.start}-{self.end}: {_one_line(exc)}"
            ) from None
        self._failures += 1
        if self._failures >= TRIES:
            raise LogReadError(
                f"{self.obj.name}: reading bytes {self.start}-{self.end} failed "
                f"{TRIES} times ({type(exc).__name__}: {_one_line(exc)})"
            ) from None
        time.sleep(RETRY_PAUSE_S * 2 ** (self._failures - 1))

    def read(self, length: int) -> bytes:
        """The next `length` bytes."""
        out = bytearray(length)
        self.readinto(memoryview(out))
        return bytes(out)

    def close(self) -> None:
        """Drop the reply (the connection too if bytes of it are left unread); count what
        was fetched (once per reply, not per read: the shared counter takes a lock)."""
        body, self._body = self._body, None
        if body is not None:
            body.close()
        if self._counter is not None and (self.pos > self._counted or self._requests):
            self._counter.add(self.pos - self._counted, self._requests)
        self._counted, self._requests = self.pos, 0


def read_range(obj: RemoteObject, start: int, end: int, counter: FetchCounter | None) -> bytes:
    """Bytes start..end-1 of `obj`, retried as `RangeStream` does."""
    stream = RangeStream(obj, start, end, counter)
    try:
        return stream.read(end - start)
    finally:
        stream.close()


def read_head(obj: RemoteObject, length: int, counter: FetchCounter | None) -> tuple[bytes, int]:
    """The first (up to) `length` bytes and the object's size, in one request."""
    stream = RangeStream(obj, 0, length, counter)
    try:
        size = stream.begin()
        stream.end = min(length, size)
        return stream.read(stream.end), size
    finally:
        stream.close()
