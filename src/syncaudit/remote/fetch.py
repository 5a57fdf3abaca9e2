"""Fetch a remote log into a local folder, for the logs that cannot be read by ranges.

An indexed MCAP is read straight from its URL (`logs.mcap.remote`: each chunk worker
streams its chunks into memory). What this module fetches is the rest: ROS 1 bags and
ROS 2 bag prefixes (metadata.yaml and its files) whole, and an MCAP without a usable
index whole; and, for the calibration (which reads point-cloud topics through a local
path), an MCAP as a sparse file: the footer and summary first, then the chunks whose
message indexes name a channel of the wanted topics (all chunks when the topics are not
known), read in coalesced ranges of at most `PIECE_BYTES` (`IN_FLIGHT` at once) and
written at their offsets into a sparse file of the remote size.
"""

from __future__ import annotations

import os
import struct
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from syncaudit.errors import LogOpenError
from syncaudit.remote.ranges import FetchStats, FsspecObject, read_range
from syncaudit.remote.urls import filesystem, public_url

MAGIC = b"\x89MCAP0\r\n"
"""An MCAP file's first and last bytes (the format's, as `mcap.writer.MCAP0_MAGIC`)."""
TAIL_BYTES = 64 << 10
"""First read of an MCAP's end: the footer, and for small logs the whole summary."""
HEAD_BYTES = 64 << 10
PIECE_BYTES = 16 << 20
"""Largest single ranged request: big enough to amortise a round trip, small enough to
keep several requests in flight."""
GAP_BYTES = 64 << 10
"""Ranges closer than this are read as one (the gap is fetched too)."""
IN_FLIGHT = 16
"""Requests fetched concurrently (at most IN_FLIGHT x PIECE_BYTES = 256 MiB in memory)."""


def _cat_ranges(fs: Any, path: str, ranges: list[tuple[int, int]], url: str) -> list[bytes]:
    """Fetch byte ranges, `IN_FLIGHT` at a time, each retried as every remote read is
    (`remote.ranges.read_range`: from where a failed reply stopped, `TRIES` attempts)."""
    obj = FsspecObject.of(fs, path, public_url(url))
    if len(ranges) == 1:
        return [read_range(obj, *ranges[0], None)]
    with ThreadPoolExecutor(min(IN_FLIGHT, len(ranges))) as pool:
        return list(pool.map(lambda r: read_range(obj, r[0], r[1], None), ranges))


def coalesce(
    ranges: list[tuple[int, int]], *, gap: int = GAP_BYTES, piece: int = PIECE_BYTES
) -> list[tuple[int, int]]:
    """Merge sorted (start, end) ranges closer than `gap`, then cut them to `piece` bytes."""
    merged: list[list[int]] = []
    for start, end in sorted(ranges):
        if merged and start - merged[-1][1] <= gap:
            merged[-1][1] = max(merged[-1][1], end)
        else:
            merged.append([start, end])
    cut = []
    for start, end in merged:
        for at in range(start, end, piece):
            cut.append((at, min(end, at + piece)))
    return cut


def fetch_log(
    url: str, folder: Path, *, topics: frozenset[str] | None = None
) -> tuple[Path, FetchStats]:
    """Bring what the audit of `url` needs into `folder`; the local path and the cost."""
    fs, path = filesystem(url)
    name = Path(urlsplit(url).path.rstrip("/")).name or "log"
    try:
        info = fs.info(path)
    except FileNotFoundError:
        raise LogOpenError(f"{public_url(url)}: no such log") from None
    except Exception as exc:
        raise LogOpenError(f"{public_url(url)}: cannot open: {exc}".splitlines()[0]) from None
    if info.get("type") == "directory" or not name.endswith((".mcap", ".bag", ".db3")):
        # A ROS 2 bag prefix (an HTTP folder is an index page to fsspec, not a directory).
        return _fetch_folder(fs, path, url, folder / name)
    size = int(info.get("size") or 0)
    target = folder / name
    if name.endswith(".mcap") and size >= 2 * len(MAGIC):
        return target, _fetch_mcap(fs, path, url, target, size, topics)
    stats = FetchStats(public_url(url), size, ranged=False)
    (data,) = _cat_ranges(fs, path, [(0, size)], url) if size else (b"",)
    target.write_bytes(data)
    stats.fetched_bytes, stats.requests = size, 1
    return target, stats


def _fetch_folder(fs: Any, path: str, url: str, target: Path) -> tuple[Path, FetchStats]:
    """A ROS 2 bag prefix: every file under it, whole."""
    files = [f for f in fs.find(path) if not f.endswith("/")]
    stats = FetchStats(public_url(url), 0, ranged=False)
    for file in sorted(files):
        size = int(fs.info(file).get("size") or 0)
        relative = file[len(path.rstrip("/")) + 1 :]
        local = target / relative
        local.parent.mkdir(parents=True, exist_ok=True)
        (data,) = _cat_ranges(fs, file, [(0, size)], url) if size else (b"",)
        local.write_bytes(data)
        stats.size_bytes += size
        stats.fetched_bytes += size
        stats.requests += 1
    return target, stats


def _fetch_mcap(
    fs: Any, path: str, url: str, target: Path, size: int, topics: frozenset[str] | None
) -> FetchStats:
    """Sparse local copy: head, summary, and the chunks holding `topics` (all if None)."""
    from mcap.reader import SeekingReader

    stats = FetchStats(public_url(url), size)
    tail_start = max(0, size - TAIL_BYTES)
    head_end = min(size, HEAD_BYTES)
    first = [(0, head_end)] if head_end <= tail_start else []
    pieces = _cat_ranges(fs, path, [*first, (tail_start, size)], url)
    stats.requests += len(pieces)
    with target.open("wb") as handle:
        handle.truncate(size)  # sparse: only fetched ranges take disk space
    fd = os.open(target, os.O_WRONLY)
    try:
        for (start, _), data in zip([*first, (tail_start, size)], pieces, strict=True):
            os.pwrite(fd, data, start)
            stats.fetched_bytes += len(data)
        tail = pieces[-1]
        if tail[-len(MAGIC) :] != MAGIC or len(tail) < len(MAGIC) + 29:
            # No footer: an unindexed MCAP is read linearly; fetch it whole.
            return _fill(fs, path, url, fd, [(0, size)], stats)
        summary_start = struct.unpack_from("<Q", tail, len(tail) - len(MAGIC) - 20)[0]
        held = [(0, head_end), (tail_start, size)]
        if 0 < summary_start < tail_start:
            held.append((summary_start, tail_start))
            (more,) = _cat_ranges(fs, path, [(summary_start, tail_start)], url)
            os.pwrite(fd, more, summary_start)
            stats.fetched_bytes += len(more)
            stats.requests += 1
        with target.open("rb") as local:
            try:
                summary = SeekingReader(local).get_summary()
            except Exception:
                summary = None
        if summary is None or not summary.chunk_indexes:
            return _fill(fs, path, url, fd, [(0, size)], stats, held)
        wanted = {
            cid
            for cid, channel in summary.channels.items()
            if topics is None
            or channel.topic in topics
            or _schema_name(summary, channel.schema_id).endswith("String")  # sensor metadata
        }
        chunks = summary.chunk_indexes
        needed = [c for c in chunks if topics is None or wanted & set(c.message_index_offsets)]
        stats.chunks_total, stats.chunks_fetched = len(chunks), len(needed)
        stats.needed_chunk_bytes = sum(c.chunk_length for c in needed)
        ranges = [(c.chunk_start_offset, c.chunk_start_offset + c.chunk_length) for c in needed]
        return _fill(fs, path, url, fd, ranges, stats, held)
    finally:
        os.close(fd)


def subtract(ranges: list[tuple[int, int]], held: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """The parts of `ranges` not inside any `held` range."""
    out = []
    for start, end in ranges:
        pieces = [(start, end)]
        for h_start, h_end in held:
            pieces = [
                part
                for a, b in pieces
                for part in ((a, min(b, h_start)), (max(a, h_end), b))
                if part[0] < part[1]
            ]
        out.extend(pieces)
    return out


def _schema_name(summary: Any, schema_id: int) -> str:
    schema = summary.schemas.get(schema_id)
    return str(schema.name) if schema is not None else ""


def _fill(
    fs: Any,
    path: str,
    url: str,
    fd: int,
    ranges: list[tuple[int, int]],
    stats: FetchStats,
    held: list[tuple[int, int]] | None = None,
) -> FetchStats:
    """Fetch coalesced ranges (less what is already `held`) and write each at its offset."""
    wanted = coalesce(subtract(ranges, held or []))
    for at in range(0, len(wanted), IN_FLIGHT):  # memory: IN_FLIGHT pieces at most
        group = wanted[at : at + IN_FLIGHT]
        for (start, _), data in zip(group, _cat_ranges(fs, path, group, url), strict=True):
            os.pwrite(fd, data, start)
            stats.fetched_bytes += len(data)
        stats.requests += len(group)
    return stats
