"""Fixtures for the log-reader tests: MCAP and rosbag2 builders, and an input-untouched check.

Helpers are handed out as fixtures because test modules cannot import each other under
`--import-mode=importlib`.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from mcap.writer import CompressionType, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

PROBE_TYPE = "probe_msgs/msg/Probe"
PROBE_DEF = "uint32 seq\nfloat64 value\nstring label\n"
"""A type that is neither in ROS nor in schemas/: readable only from a log's own definition."""


@dataclass(frozen=True)
class Channel:
    """One MCAP channel to write: topic, schema and encodings."""

    topic: str
    schema_name: str
    schema_encoding: str = "ros2msg"
    schema_text: str = ""
    message_encoding: str = "cdr"


@dataclass(frozen=True)
class Written:
    """A message as written: topic, log time and serialized bytes."""

    topic: str
    log_time: int
    data: bytes


def _write_mcap(
    path: Path, channels: list[Channel], messages: Iterable[Written], **writer_args: Any
) -> list[Written]:
    """Write an MCAP with the `mcap` writer; returns the messages in write order."""
    written = list(messages)
    writer_args.setdefault("compression", CompressionType.ZSTD)
    with path.open("wb") as handle:
        writer = Writer(handle, **writer_args)
        writer.start(profile="ros2", library="syncaudit-tests")
        ids: dict[str, int] = {}
        for ch in channels:
            schema_id = 0
            if ch.schema_name:
                schema_id = writer.register_schema(
                    ch.schema_name, ch.schema_encoding, ch.schema_text.encode()
                )
            ids[ch.topic] = writer.register_channel(ch.topic, ch.message_encoding, schema_id)
        for seq, msg in enumerate(written):
            writer.add_message(
                ids[msg.topic],
                log_time=msg.log_time,
                data=msg.data,
                publish_time=msg.log_time,
                sequence=seq,
            )
        writer.finish()
    return written


@pytest.fixture
def write_mcap() -> Callable[..., list[Written]]:
    """`write_mcap(path, channels, messages, **Writer args)`: build an MCAP file."""
    return _write_mcap


@pytest.fixture(scope="session")
def ros2_store() -> Typestore:
    """ROS 2 Humble types plus the probe type, for serialising test messages."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    store.register(get_types_from_msg(PROBE_DEF, PROBE_TYPE))
    return store


@pytest.fixture(scope="session")
def ros1_store() -> Typestore:
    """ROS 1 Noetic types, for serialising ROS 1 test messages."""
    return get_typestore(Stores.ROS1_NOETIC)


@pytest.fixture
def probe(ros2_store: Typestore) -> Callable[[int], bytes]:
    """`probe(i)`: CDR bytes of a probe message with seq i (label f'p{i}')."""
    cls = ros2_store.types[PROBE_TYPE]

    def make(i: int) -> bytes:
        msg = cls(seq=i, value=i / 2, label=f"p{i}")
        return bytes(ros2_store.serialize_cdr(msg, PROBE_TYPE))

    return make


def _snapshot(path: Path) -> dict[str, tuple[str, int]]:
    """sha256 and mtime of every file at/under `path`, by relative name (dirs: also new files)."""
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    return {
        str(p.relative_to(path.parent)): (
            hashlib.sha256(p.read_bytes()).hexdigest(),
            p.stat().st_mtime_ns,
        )
        for p in files
    }


@pytest.fixture
def untouched() -> Iterator[Callable[[Path], Path]]:
    """`untouched(path)`: assert at teardown that path's files kept bytes and mtimes.

    For a directory the set of files must not change either (no -wal/-shm side files).
    """
    watched: list[tuple[Path, dict[str, tuple[str, int]]]] = []

    def watch(path: Path) -> Path:
        watched.append((path, _snapshot(path)))
        return path

    yield watch
    for path, before in watched:
        assert _snapshot(path) == before, f"{path} was modified by reading it"
