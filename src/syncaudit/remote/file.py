"""A remote object as a seekable, cached, read-only file; the runs of it a worker streams.

`RemoteFile.open(url, head_bytes)` fetches the object's first bytes and learns its size in
one request; the format readers then read it as they read a local file (the mcap library,
the ROS 1 bag reader). What they read is kept (`RemoteSource.segments`: head, footer,
summary, index; at least `MISS_BYTES` a miss), so the index costs a few requests however
large the log; what they `hold` is fetched ahead in one request. `RunStream` gives a run
of bytes in order, those held from memory and each stretch between them by one ranged
GET. Every read is retried by `remote.ranges`' one policy and counted in the source's
`FetchCounter`, in shared memory, so `RemoteSource.stats()` covers the forked workers too.

An object open in this process is one `RemoteSource`, however many logs open it: a second
open of a log (the audit's, inside the gate's) reuses the bytes the first fetched, and a
forked worker finds its parent's source (the URL to ask with, the counter, the bytes held)
by the public URL its read units carry (`shared_source`). The source goes when its last
file closes. Nothing here knows a log format.
"""

from __future__ import annotations

import io
import threading
from dataclasses import dataclass, field

from syncaudit.errors import LogOpenError
from syncaudit.remote.ranges import (
    FetchCounter,
    FetchStats,
    RangeStream,
    RemoteObject,
    open_object,
    read_head,
    read_range,
)
from syncaudit.remote.urls import public_url

MISS_BYTES = 4 << 10
"""Smallest read outside what is held (a miss reads on a little: message indexes)."""


class RemoteUnindexedError(LogOpenError):
    """A remote log without a usable index: it can only be read whole (downloaded first)."""

    def __init__(self, message: str, whole_reason: str) -> None:
        super().__init__(message)
        self.whole_reason = whole_reason
        """Why the log is not read by ranges (the `remote_read.whole_reason` of the gate)."""


@dataclass(eq=False, slots=True)
class RemoteSource:
    """One remote object open in this process: the URL as given (a signed URL's query
    string: never shown), its size, the bytes kept, and what reading it has cost."""

    url: str
    obj: RemoteObject
    size_bytes: int
    counter: FetchCounter
    segments: dict[int, bytes] = field(default_factory=dict)
    """Start offset -> bytes fetched and kept (head, summary, index, the parent's chunks)."""
    cached_bytes: int = 0
    """Bytes of chunks among `segments` (bounded by the reader that keeps them)."""
    needed_chunk_bytes: int = 0
    chunks_fetched: int = 0
    chunks_total: int = 0
    users: int = 0

    @property
    def name(self) -> str:
        """The URL as messages show it (no query string, no user info)."""
        return public_url(self.url)

    def note_chunks(self, total: int, fetched: int, needed_bytes: int) -> None:
        """What the reader's read units need of the object's chunks (for `stats`)."""
        self.chunks_total, self.chunks_fetched = total, fetched
        self.needed_chunk_bytes = needed_bytes

    def stats(self) -> FetchStats:
        """Bytes and requests fetched so far (by every process) against the needed chunks."""
        return FetchStats(
            url=self.name,
            size_bytes=self.size_bytes,
            fetched_bytes=self.counter.fetched_bytes,
            requests=self.counter.requests,
            needed_chunk_bytes=self.needed_chunk_bytes,
            chunks_fetched=self.chunks_fetched,
            chunks_total=self.chunks_total,
        )


_OPEN: dict[str, RemoteSource] = {}
"""The remote objects open in this process (and, after a fork, in its parent), by public
URL: the cache every open of one object shares."""
_OPEN_LOCK = threading.Lock()


def open_source(url: str, head_bytes: int) -> RemoteSource:
    """`url`'s source in this process, its first `head_bytes` fetched when it is new."""
    key = public_url(url)
    with _OPEN_LOCK:
        source = _OPEN.get(key)
        if source is not None:
            source.users += 1
            return source
    counter = FetchCounter()
    obj = open_object(url)
    head, size = read_head(obj, head_bytes, counter)
    fresh = RemoteSource(url, obj, size, counter, {0: head} if head else {})
    with _OPEN_LOCK:
        source = _OPEN.setdefault(key, fresh)
        source.users += 1
        return source


def release_source(source: RemoteSource) -> None:
    """Drop one use of a source; the last use forgets it."""
    key = source.name
    with _OPEN_LOCK:
        source.users -= 1
        if source.users <= 0 and _OPEN.get(key) is source:
            del _OPEN[key]


def shared_source(url: str) -> RemoteSource | None:
    """The source of `url` (public or as given) if this process, or the parent it forked
    from, has it open."""
    return _OPEN.get(public_url(url))


def signed_url(url: str) -> str:
    """The URL the object was opened with (query string, user info) for its public form,
    where this process has it open; else `url` itself.

    Read units carry the public URL only (they may be shown); a worker turns it back into
    the URL it must ask with here. A forked worker inherits the source; a spawned worker
    gets the URL in its task (never shown) and opens the log with it first."""
    source = shared_source(url)
    return source.url if source is not None else url


class RemoteFile:
    """A read-only, seekable file over a remote object: held bytes from memory, anything
    else by a ranged read (kept, for the index reads that follow).

    Not an `io.RawIOBase`: the mcap library wraps those in a BufferedReader, which reads
    ahead past what is needed and closes the file when it is dropped.
    """

    def __init__(self, source: RemoteSource, *, owner: bool = False) -> None:
        self.source = source
        self.name = source.name
        self.size = source.size_bytes
        self._owner = owner
        """This file holds a use of the source (released by `close`)."""
        self._pos = 0
        self.closed = False

    @classmethod
    def open(cls, url: str, head_bytes: int) -> RemoteFile:
        """The object behind `url`, its first `head_bytes` fetched (when not yet open)."""
        return cls(open_source(url, head_bytes), owner=True)

    def readable(self) -> bool:
        """Yes."""
        return True

    def seekable(self) -> bool:
        """Yes."""
        return True

    def tell(self) -> int:
        """The read position."""
        return self._pos

    def seek(self, offset: int, whence: int = io.SEEK_SET) -> int:
        """Move the read position."""
        base = {io.SEEK_SET: 0, io.SEEK_CUR: self._pos, io.SEEK_END: self.size}[whence]
        self._pos = max(0, base + offset)
        return self._pos

    def read(self, size: int = -1) -> bytes:
        """Up to `size` bytes from the read position (to the end if negative)."""
        end = self.size if size < 0 else min(self.size, self._pos + size)
        if end <= self._pos:
            return b""
        start, self._pos = self._pos, end
        return bytes(self._slice(start, end))

    def readinto(self, buffer: bytearray | memoryview) -> int:
        """Fill a prefix of `buffer`; the bytes read."""
        n = min(len(buffer), self.size - self._pos)
        if n <= 0:
            return 0
        buffer[:n] = self._slice(self._pos, self._pos + n)
        self._pos += n
        return n

    def held(self, start: int, end: int) -> memoryview | None:
        """Bytes start..end-1 if one kept segment holds them all."""
        for at, data in self.source.segments.items():
            if at <= start and end <= at + len(data):
                return memoryview(data)[start - at : end - at]
        return None

    def hold(self, start: int, end: int) -> None:
        """Fetch bytes start..end-1 in one request and keep them (joined to a kept segment
        that starts at `end`, so reads across the two are served from memory), unless
        they are kept already."""
        if start >= end or self.held(start, end) is not None:
            return
        data = read_range(self.source.obj, start, end, self.source.counter)
        segments = self.source.segments
        segments[start] = data + segments.pop(end, b"")

    def close(self) -> None:
        """Release the source (the last file of it to close forgets its bytes)."""
        if not self.closed:
            self.closed = True
            if self._owner:
                release_source(self.source)

    def _slice(self, start: int, end: int) -> memoryview:
        held = self.held(start, end)
        if held is not None:
            return held
        stop = min(self.size, max(end, start + MISS_BYTES))
        data = read_range(self.source.obj, start, stop, self.source.counter)
        self.source.segments[start] = data
        return memoryview(data)[: end - start]


class RunStream:
    """The bytes of a run, in order: those the source holds (head, tail, chunks the
    parent's own reads kept) from memory, each stretch between them by one ranged GET."""

    def __init__(
        self, obj: RemoteObject, start: int, end: int, source: RemoteSource | None
    ) -> None:
        self.pos = start
        segments = source.segments.items() if source is not None else ()
        self._held = sorted(
            (at, data) for at, data in segments if at < end and start < at + len(data)
        )
        self._obj = obj
        self._counter = source.counter if source is not None else None
        self._net: RangeStream | None = None
        self._gaps: list[tuple[int, int]] = []
        at = start
        for seg_start, data in self._held:
            if seg_start > at:
                self._gaps.append((at, min(seg_start, end)))
            at = max(at, seg_start + len(data))
        if at < end:
            self._gaps.append((at, end))

    def readinto(self, buffer: memoryview) -> None:
        """Fill `buffer` exactly with the next bytes of the run."""
        while len(buffer):
            gap = next(((a, b) for a, b in self._gaps if a <= self.pos < b), None)
            if gap is not None:
                net = self._net
                if net is None or net.start != gap[0]:
                    self.close()
                    net = self._net = RangeStream(self._obj, gap[0], gap[1], self._counter)
                n = min(len(buffer), gap[1] - self.pos)
                net.readinto(buffer[:n])
            else:
                at, data = next((a, d) for a, d in self._held if a <= self.pos < a + len(d))
                n = min(len(buffer), at + len(data) - self.pos)
                buffer[:n] = data[self.pos - at : self.pos - at + n]
            buffer = buffer[n:]
            self.pos += n

    def close(self) -> None:
        """Drop the reply."""
        if self._net is not None:
            self._net.close()
            self._net = None


def read_run(obj: RemoteObject, start: int, end: int, source: RemoteSource | None) -> bytearray:
    """Bytes start..end-1 as `RunStream` gives them, into a new buffer."""
    out = bytearray(end - start)
    stream = RunStream(obj, start, end, source)
    try:
        stream.readinto(memoryview(out))
    finally:
        stream.close()
    return out
