"""Fixtures for the log-reader tests: typestores, probe messages, an input-untouched check.

Shared helpers are handed out as fixtures because test modules cannot import each other
under `--import-mode=importlib`.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

PROBE_TYPE = "probe_msgs/msg/Probe"
PROBE_DEF = "uint32 seq\nfloat64 value\nstring label\n"
"""A type that is neither in ROS nor in schemas/: readable only from a log's own definition."""


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


@dataclass(frozen=True)
class ProbeKit:
    """The probe type: its name, its .msg text, and `make(i)` giving CDR bytes of one."""

    type: str
    definition: str
    make: Callable[[int], bytes]


@pytest.fixture(scope="session")
def probe(ros2_store: Typestore) -> ProbeKit:
    """Probe messages: seq i, value i/2, label f'p{i}'."""
    cls = ros2_store.types[PROBE_TYPE]

    def make(i: int) -> bytes:
        msg = cls(seq=i, value=i / 2, label=f"p{i}")
        return bytes(ros2_store.serialize_cdr(msg, PROBE_TYPE))

    return ProbeKit(PROBE_TYPE, PROBE_DEF, make)


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
