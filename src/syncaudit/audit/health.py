"""`LogHealth`: what the readers found wrong with the file itself, as a record.

The readers say it in `LogWarning`s (a code and a sentence) and the camera extraction in
lines counting the damaged messages it skipped; the audit prints them, but a gate needs
them as data: was the log cut off (and where), which topics lost damaged messages and how
many, was a chunk cut or its index missing. A CRC mismatch stops the read (an error, not
a warning); `bad_crc` counts the ones a reader reported and read on, and `info --check-crc`
verifies every indexed MCAP chunk (`check_chunk_crcs`), as `mcap doctor` does, listing
every bad chunk by its byte offset. One record for `audit`, `info` and the gate.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from syncaudit.errors import LogReadError, NoDataError, SyncauditError
from syncaudit.logs.base import LogReader
from syncaudit.logs.model import LogWarning

TRUNCATED_CODES = frozenset({"mcap-truncated", "rosbag1-truncated", "rosbag2-sqlite-damaged"})
"""The file ends (or its database is unreadable) before its end: only what precedes is read."""
CUT_CHUNK_CODES = frozenset({"rosbag1-damaged"})
"""A chunk is damaged or cut; the messages before it are read."""
NO_INDEX_CODES = frozenset({"mcap-no-summary", "mcap-bad-summary", "rosbag1-no-index"})
"""The index (MCAP summary, ROS 1 index records) is missing or unreadable: read linearly."""
DAMAGED_CODES = frozenset({"mcap-unknown-channel", "rosbag1-unknown-connection"})
"""Records that refer to what the file never defined: damaged, read around."""


@dataclass(frozen=True, slots=True)
class CrcCheck:
    """Every indexed chunk's CRC verified (`info --check-crc`)."""

    checked_chunks: int | None
    """Chunks verified (None: not checked, `note` says why)."""
    bad_chunks: tuple[int, ...] = ()
    """Byte offsets of chunks whose records do not match their CRC or size."""
    note: str | None = None


_BYTE = re.compile(r"\bbyte (\d+)")
_DAMAGED = re.compile(r"(\d+) damaged messages? skipped on (\S+)")


@dataclass(frozen=True, slots=True)
class LogHealth:
    """The condition of one log file (empty lists and False: intact)."""

    truncated: bool = False
    cut_at_byte: int | None = None
    """Where the cut-off part starts (the first incomplete record), when the reader says."""
    cut_chunks: int = 0
    damaged_messages: dict[str, int] = field(default_factory=dict)
    """Per topic, messages skipped because their bytes did not decode."""
    bad_crc: int = 0
    missing_index: bool = False
    damaged: tuple[str, ...] = ()
    """Damage read around, or what stopped the read (a chunk that does not decompress)."""
    crc: CrcCheck | None = None
    """The chunk CRCs verified on request (None: not asked)."""
    notes: tuple[str, ...] = ()
    """The readers' own sentences behind the record."""

    @property
    def damaged_total(self) -> int:
        """Damaged messages skipped over all topics."""
        return sum(self.damaged_messages.values())

    @property
    def bad_crc_chunks(self) -> tuple[int, ...]:
        """Offsets of the chunks a CRC check found bad."""
        return () if self.crc is None else self.crc.bad_chunks

    @property
    def status(self) -> str:
        """'ok', 'truncated', 'damaged' or 'bad-crc': the worst condition seen."""
        if self.bad_crc or self.bad_crc_chunks:
            return "bad-crc"
        # A chunk cut by the file's end is the truncation itself, not damage inside it.
        if self.damaged or self.damaged_messages or (self.cut_chunks and not self.truncated):
            return "damaged"
        return "truncated" if self.truncated else "ok"

    @property
    def intact(self) -> bool:
        """Nothing was cut, skipped, damaged or read without its index."""
        return not self.problems

    @property
    def problems(self) -> list[str]:
        """One short phrase per condition, for summaries ('cut off at byte 597772')."""
        out = []
        if self.truncated:
            where = f" at byte {self.cut_at_byte}" if self.cut_at_byte is not None else ""
            out.append(f"cut off{where}")
        if self.cut_chunks:
            out.append(f"{self.cut_chunks} cut or damaged chunk(s)")
        for topic, count in sorted(self.damaged_messages.items()):
            out.append(f"{count} damaged message(s) skipped on {topic}")
        if self.bad_crc or self.bad_crc_chunks:
            out.append(f"{self.bad_crc + len(self.bad_crc_chunks)} bad CRC(s)")
        out.extend(self.damaged)
        if self.missing_index:
            out.append("no index (read linearly)")
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON form (schemas/audit.schema.json `health`)."""
        return {
            "intact": self.intact,
            "truncated": self.truncated,
            "cut_at_byte": self.cut_at_byte,
            "cut_chunks": self.cut_chunks,
            "damaged_messages": dict(sorted(self.damaged_messages.items())),
            "damaged_total": self.damaged_total,
            "bad_crc": self.bad_crc,
            "missing_index": self.missing_index,
            "status": self.status,
            "damaged": list(self.damaged),
            "crc_checked_chunks": None if self.crc is None else self.crc.checked_chunks,
            "bad_crc_chunks": list(self.bad_crc_chunks),
            "crc_note": None if self.crc is None else self.crc.note,
            "problems": self.problems,
            "notes": list(self.notes),
        }


def log_health(
    reader_warnings: Iterable[LogWarning],
    skipped: Iterable[str] = (),
    *,
    failure: Exception | None = None,
    crc_check: CrcCheck | None = None,
) -> LogHealth:
    """The record from the readers' warnings and the extraction's 'N damaged messages
    skipped on TOPIC' lines (other lines are ignored); `failure` is what stopped reading
    the LiDAR (a LogReadError there is damage too), `crc_check` a `check_chunk_crcs`."""
    truncated, cut_at, cut_chunks, crc, no_index = False, None, 0, 0, False
    notes: list[str] = []
    damage: list[str] = []
    if isinstance(failure, LogReadError):
        damage.append(" ".join(str(failure).split()))
    for warning in reader_warnings:
        code = warning.code
        if code in TRUNCATED_CODES:
            truncated = True
            found = _BYTE.search(warning.message)
            if found and cut_at is None:
                cut_at = int(found.group(1))
            if "inside a chunk" in warning.message:
                cut_chunks += 1
        elif code in CUT_CHUNK_CODES:
            cut_chunks += 1
        elif code in NO_INDEX_CODES:
            no_index = True
        elif code in DAMAGED_CODES:
            damage.append(warning.message)
        elif "crc" in code:
            crc += 1
        else:
            continue
        notes.append(warning.message)
    damaged: dict[str, int] = {}
    for line in skipped:
        found = _DAMAGED.search(line)
        if found:
            topic = found.group(2)
            damaged[topic] = damaged.get(topic, 0) + int(found.group(1))
            notes.append(line)
    return LogHealth(
        truncated,
        cut_at,
        cut_chunks,
        damaged,
        crc,
        no_index,
        tuple(damage),
        crc_check,
        tuple(notes),
    )


def check_chunk_crcs(log: LogReader) -> CrcCheck:
    """Verify every chunk a local MCAP's index lists; say why not where it cannot."""
    from syncaudit.logs.mcap.chunks import ChunkReader
    from syncaudit.logs.mcap.reader import McapLog

    if not isinstance(log, McapLog):
        return CrcCheck(
            None, note=f"no chunk CRCs checked: a {log.summary.container} log holds none"
        )
    if not Path(str(log.path)).is_file():
        return CrcCheck(None, note="no chunk CRCs checked: a remote MCAP (use audit --check-crc)")
    summary = log.indexed_summary()
    if summary is None:
        return CrcCheck(None, note="no chunk CRCs checked: the MCAP has no chunk index")
    reader = ChunkReader(str(log.path), check_crc=True, reuse=False)
    bad: list[int] = []
    try:
        indexes = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
        for index in indexes:
            try:
                reader.read(index.chunk_start_offset, index.chunk_length)
            except LogReadError:
                bad.append(index.chunk_start_offset)
    finally:
        reader.close()
    return CrcCheck(len(indexes), tuple(bad))


def no_packets_error(log: LogReader, topic: str) -> SyncauditError:
    """The error for a LiDAR topic that gave no packets, saying why where the log knows.

    A log cut off or damaged before the topic's first packet is a damaged log (exit 3),
    named with where it was cut (`... cut off at byte 50000`); otherwise the topic is
    simply empty (NoDataError, exit 7).
    """
    for warning in log.warnings:
        if warning.code in TRUNCATED_CODES | CUT_CHUNK_CODES | DAMAGED_CODES | {"mcap-bad-summary"}:
            why = warning.message.split("; reading")[0]
            return LogReadError(f"{why}: LiDAR topic {topic} holds no packets before it")
    return NoDataError(f"LiDAR topic {topic} holds no packets")
