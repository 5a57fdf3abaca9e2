"""`LogHealth`: what the readers found wrong with the file itself, as a record.

The readers say it in `LogWarning`s (a code and a sentence) and the camera extraction in
lines counting the damaged messages it skipped; the audit prints them, but a gate needs
them as data: was the log cut off (and where), which topics lost damaged messages and how
many, was a chunk cut or its index missing. A CRC mismatch stops the read (an error, not
a warning); `bad_crc` counts the ones a reader reported and read on.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from syncaudit.logs.model import LogWarning

TRUNCATED_CODES = frozenset({"mcap-truncated", "rosbag1-truncated", "rosbag2-sqlite-damaged"})
"""The file ends (or its database is unreadable) before its end: only what precedes is read."""
CUT_CHUNK_CODES = frozenset({"rosbag1-damaged"})
"""A chunk is damaged or cut; the messages before it are read."""
NO_INDEX_CODES = frozenset({"mcap-no-summary", "mcap-bad-summary", "rosbag1-no-index"})
"""The index (MCAP summary, ROS 1 index records) is missing or unreadable: read linearly."""

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
    notes: tuple[str, ...] = ()
    """The readers' own sentences behind the record."""

    @property
    def damaged_total(self) -> int:
        """Damaged messages skipped over all topics."""
        return sum(self.damaged_messages.values())

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
        if self.bad_crc:
            out.append(f"{self.bad_crc} bad CRC(s)")
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
            "problems": self.problems,
            "notes": list(self.notes),
        }


def log_health(reader_warnings: Iterable[LogWarning], skipped: Iterable[str] = ()) -> LogHealth:
    """The record from the readers' warnings and the extraction's 'N damaged messages
    skipped on TOPIC' lines (other lines are ignored)."""
    truncated, cut_at, cut_chunks, crc, no_index = False, None, 0, 0, False
    notes: list[str] = []
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
    return LogHealth(truncated, cut_at, cut_chunks, damaged, crc, no_index, tuple(notes))
