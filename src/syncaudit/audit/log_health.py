"""A log's health as `info` reports it: truncation, damage and (on request) chunk CRCs.

Built from the readers' `LogWarning` codes (what opening and reading the index saw) and, with
`check_crc`, from verifying every indexed MCAP chunk's CRC, as `mcap doctor` does: every bad
chunk is listed by its byte offset, not just the first.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from syncaudit.errors import LogReadError, NoDataError, SyncauditError
from syncaudit.logs.base import LogReader

TRUNCATED_CODES = frozenset({"mcap-truncated", "rosbag1-truncated"})
"""Warning codes saying the file was cut off (a recording interrupted)."""

DAMAGED_CODES = frozenset(
    {
        "mcap-bad-summary",
        "mcap-unknown-channel",
        "rosbag1-damaged",
        "rosbag1-unknown-connection",
        "rosbag2-sqlite-damaged",
    }
)
"""Warning codes saying records inside the file are damaged or inconsistent."""


@dataclass(slots=True)
class LogHealth:
    """What `info` saw wrong with a log's bytes (empty lists: nothing)."""

    status: str
    """'ok', 'truncated', 'damaged' or 'bad-crc' (the worst seen, in that order)."""
    truncated: list[str] = field(default_factory=list)
    damaged: list[str] = field(default_factory=list)
    crc_checked_chunks: int | None = None
    """Chunks whose CRC was verified (None: not checked, or the format has none)."""
    bad_crc_chunks: list[int] = field(default_factory=list)
    """Byte offsets of chunks whose records do not match their CRC or size."""
    crc_note: str | None = None
    """Why CRCs were not checked although asked (no index, no CRCs in this format)."""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return asdict(self)


def log_health(
    log: LogReader, *, check_crc: bool = False, failure: Exception | None = None
) -> LogHealth:
    """The health of an open log; `check_crc` verifies every indexed MCAP chunk's CRC.

    `failure` is what stopped reading the log's LiDAR, if anything: a LogReadError there
    (a chunk that does not decompress, a record that does not parse) is damage too.
    """
    health = LogHealth(status="ok")
    if isinstance(failure, LogReadError):
        health.damaged.append(" ".join(str(failure).split()))
    for warning in log.warnings:
        if warning.code in TRUNCATED_CODES:
            health.truncated.append(warning.message)
        elif warning.code in DAMAGED_CODES:
            health.damaged.append(warning.message)
    if check_crc:
        _check_crcs(log, health)
    if health.bad_crc_chunks:
        health.status = "bad-crc"
    elif health.damaged:
        health.status = "damaged"
    elif health.truncated:
        health.status = "truncated"
    return health


def _check_crcs(log: LogReader, health: LogHealth) -> None:
    """Verify every chunk the MCAP index lists; note why not where it cannot."""
    from syncaudit.logs.mcap.chunks import ChunkReader
    from syncaudit.logs.mcap.reader import McapLog

    if not isinstance(log, McapLog):
        health.crc_note = f"no chunk CRCs checked: a {log.summary.container} log holds none"
        return
    if not Path(str(log.path)).is_file():
        health.crc_note = "no chunk CRCs checked: a remote MCAP (use audit --check-crc)"
        return
    summary = log.indexed_summary()
    if summary is None:
        health.crc_note = "no chunk CRCs checked: the MCAP has no chunk index"
        return
    reader = ChunkReader(str(log.path), check_crc=True, reuse=False)
    try:
        checked = 0
        for index in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
            checked += 1
            try:
                reader.read(index.chunk_start_offset, index.chunk_length)
            except LogReadError:
                health.bad_crc_chunks.append(index.chunk_start_offset)
        health.crc_checked_chunks = checked
    finally:
        reader.close()


def no_packets_error(log: LogReader, topic: str) -> SyncauditError:
    """The error for a LiDAR topic that gave no packets, saying why where the log knows.

    A log cut off or damaged before the topic's first packet is a damaged log (exit 3),
    named with where it was cut (`... cut off at byte 50000`); otherwise the topic is
    simply empty (NoDataError, exit 7).
    """
    for warning in log.warnings:
        if warning.code in TRUNCATED_CODES or warning.code in DAMAGED_CODES:
            why = warning.message.split("; reading")[0]
            return LogReadError(f"{why}: LiDAR topic {topic} holds no packets before it")
    return NoDataError(f"LiDAR topic {topic} holds no packets")
