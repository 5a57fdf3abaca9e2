"""A remote object as a read-only, seekable file, and the runs of bytes a worker streams.

`RemoteFile` serves what the parent already fetched (head, tail, summary, index: kept in
the log's `Tracker`) from memory and anything else by a ranged read (`remote.ranges`:
retried, counted); the format readers read it as they read a local file. `RunStream`
gives a run of bytes in order, those held from memory and each stretch between them by
one ranged GET. Neither knows a log format.
"""

from __future__ import annotations

import io

from syncaudit.errors import LogOpenError
from syncaudit.remote.ranges import RangeStream, RemoteObject, Tracker, read_range

MISS_BYTES = 4 << 10
"""Smallest read of the parent outside head, tail and summary (message indexes)."""


class RemoteUnindexedError(LogOpenError):
    """A remote log without a usable index: it can only be read whole (downloaded first)."""


class RemoteFile:
    """A read-only, seekable view of a remote object (for the mcap library, the ROS 1 bag
    reader): the bytes the parent fetched (head, tail, summary, index), anything else by a
    ranged read.

    Not an `io.RawIOBase`: the mcap library wraps those in a BufferedReader, which reads
    ahead past what is needed and closes the file when it is dropped.
    """

    def __init__(
        self, obj: RemoteObject, size: int, tracker: Tracker, *, keep: bool = True
    ) -> None:
        self._obj, self._size, self._tracker = obj, size, tracker
        self._keep = keep
        """Keep what a miss fetched (the parent's index reads; not a worker's chunks)."""
        self._pos = 0
        self.closed = False

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
        base = {io.SEEK_SET: 0, io.SEEK_CUR: self._pos, io.SEEK_END: self._size}[whence]
        self._pos = max(0, base + offset)
        return self._pos

    def read(self, size: int = -1) -> bytes | bytearray:
        """Up to `size` bytes from the read position (to the end if negative)."""
        end = self._size if size < 0 else min(self._size, self._pos + size)
        if end <= self._pos:
            return b""
        start, self._pos = self._pos, end
        if not self._keep and self._held(start, end) is None:
            # A worker's chunk: streamed straight into the buffer returned (no second copy).
            out = bytearray(end - start)
            stream = RunStream(self._obj, start, end, self._tracker)
            try:
                stream.readinto(memoryview(out))
            finally:
                stream.close()
            return out
        return bytes(self._slice(start, end))

    def readinto(self, buffer: bytearray | memoryview) -> int:
        """Fill a prefix of `buffer`; the bytes read."""
        n = min(len(buffer), self._size - self._pos)
        if n <= 0:
            return 0
        buffer[:n] = self._slice(self._pos, self._pos + n)
        self._pos += n
        return n

    def close(self) -> None:
        """Nothing held open (the fetched bytes belong to the tracker)."""
        self.closed = True

    def _held(self, start: int, end: int) -> memoryview | None:
        """Bytes start..end-1 if one fetched segment holds them all."""
        for at, data in self._tracker.segments.items():
            if at <= start and end <= at + len(data):
                return memoryview(data)[start - at : end - at]
        return None

    def _slice(self, start: int, end: int) -> memoryview:
        held = self._held(start, end)
        if held is not None:
            return held
        stop = min(self._size, max(end, start + MISS_BYTES))
        if not self._keep:
            return memoryview(read_range(self._obj, start, end, self._tracker.counter))
        data = read_range(self._obj, start, stop, self._tracker.counter)
        self._tracker.segments[start] = data
        return memoryview(data)[: end - start]


class RunStream:
    """The bytes of a run, in order: those the parent already holds (head, tail, chunks
    its own `messages()` read) from memory, each stretch between them by one ranged GET."""

    def __init__(self, obj: RemoteObject, start: int, end: int, tracker: Tracker | None) -> None:
        self.pos = start
        segments = tracker.segments.items() if tracker is not None else ()
        self._held = sorted(
            (at, data) for at, data in segments if at < end and start < at + len(data)
        )
        self._obj = obj
        self._counter = tracker.counter if tracker is not None else None
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
