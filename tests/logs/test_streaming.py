"""Streaming sanity (not timed): messages() is a generator that never holds the log in memory.

Each log is ~15 MB of incompressible payload in many chunks; Python-heap peaks (tracemalloc)
while opening, taking the first message and reading everything must stay a small fraction
of it. sqlite's own page cache is outside the Python heap, so for .db3 this checks what
rosbags hands up, not sqlite itself (which pages the file on demand).
"""

from __future__ import annotations

import gc
import inspect
import random
import tracemalloc
from collections.abc import Callable
from pathlib import Path

import pytest
from mcap.writer import CompressionType, IndexType, Writer
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import Writer as Ros2Writer
from rosbags.typesys import Stores, get_typestore

from syncaudit.logs import open_log

PAYLOAD = 25_000
COUNT = 600  # 15 MB
BUDGET = 4_000_000  # bytes of Python heap a reader may peak at


def payloads() -> list[bytes]:
    rng = random.Random(1234)
    return [rng.randbytes(PAYLOAD) for _ in range(COUNT)]


def _mcap(path: Path, **extra: object) -> None:
    with path.open("wb") as handle:
        writer = Writer(handle, chunk_size=100_000, compression=CompressionType.NONE, **extra)  # type: ignore[arg-type]
        writer.start(profile="ros2", library="syncaudit-tests")
        schema = writer.register_schema("std_msgs/msg/String", "ros2msg", b"string data\n")
        channel = writer.register_channel("/blob", "cdr", schema)
        for i, data in enumerate(payloads()):
            writer.add_message(channel, log_time=i * 1_000, data=data, publish_time=i * 1_000)
        writer.finish()


def build(kind: str, folder: Path) -> Path:
    """Write one ~15 MB log of the given kind; returns what to pass to open_log."""
    if kind == "mcap-indexed":
        path = folder / "indexed.mcap"
        _mcap(path)
    elif kind == "mcap-no-summary":
        path = folder / "linear.mcap"
        _mcap(path, use_summary_offsets=False, use_statistics=False, index_types=IndexType.NONE)
    elif kind == "mcap-cut":
        full = folder / "full.mcap"
        _mcap(full)
        path = folder / "cut.mcap"
        path.write_bytes(full.read_bytes()[: full.stat().st_size * 9 // 10])
    elif kind == "rosbag2-sqlite3":
        path = folder / "bag2"
        store = get_typestore(Stores.ROS2_HUMBLE)
        with Ros2Writer(path, version=9) as writer:
            conn = writer.add_connection("/blob", "std_msgs/msg/String", typestore=store)
            for i, data in enumerate(payloads()):
                writer.write(conn, i * 1_000, data)
    else:
        path = folder / "bag1.bag"
        store = get_typestore(Stores.ROS1_NOETIC)
        with Ros1Writer(path) as writer:
            conn = writer.add_connection("/blob", "std_msgs/msg/String", typestore=store)
            for i, data in enumerate(payloads()):
                writer.write(conn, i * 1_000 + 1_000_000_000, data)
    return path


KINDS = ["mcap-indexed", "mcap-no-summary", "mcap-cut", "rosbag2-sqlite3", "rosbag1"]


@pytest.fixture(scope="module")
def big_logs(tmp_path_factory: pytest.TempPathFactory) -> Callable[[str], Path]:
    folder = tmp_path_factory.mktemp("big")
    built: dict[str, Path] = {}

    def get(kind: str) -> Path:
        if kind not in built:
            built[kind] = build(kind, folder)
        return built[kind]

    return get


def _size(path: Path) -> int:
    return sum(p.stat().st_size for p in ([path] if path.is_file() else path.iterdir()))


@pytest.mark.parametrize("kind", KINDS)
def test_messages_stream_in_bounded_memory(kind: str, big_logs: Callable[[str], Path]) -> None:
    path = big_logs(kind)
    assert _size(path) > 3 * BUDGET
    gc.collect()
    tracemalloc.start()
    try:
        with open_log(path) as log:
            opened = tracemalloc.get_traced_memory()[1]
            stream = log.messages()
            assert inspect.isgenerator(stream)
            tracemalloc.reset_peak()
            first = next(stream)
            first_peak = tracemalloc.get_traced_memory()[1]
            count, total = 1, len(first.data)
            previous = first.log_time_ns
            for msg in stream:
                assert msg.log_time_ns >= previous
                previous = msg.log_time_ns
                count += 1
                total += len(msg.data)
            read_peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    expected = COUNT if kind != "mcap-cut" else log.summary.message_count
    assert count == expected and total == expected * PAYLOAD
    if kind == "mcap-cut":
        assert COUNT * 0.85 < count < COUNT
    for stage, peak in [("open", opened), ("first message", first_peak), ("full read", read_peak)]:
        assert peak < BUDGET, f"{kind}: {stage} peaked at {peak / 1e6:.1f} MB of Python heap"


def test_time_window_on_indexed_mcap_reads_only_its_chunks(
    big_logs: Callable[[str], Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A window of 10 messages out of 600 reads a few chunks, not the file."""
    path = big_logs("mcap-indexed")
    with open_log(path) as log:
        handle = log._file  # type: ignore[attr-defined]
        read_bytes = 0
        real_read = handle.read

        def counting_read(size: int = -1) -> bytes:
            nonlocal read_bytes
            data: bytes = real_read(size)
            read_bytes += len(data)
            return data

        monkeypatch.setattr(handle, "read", counting_read)
        got = [m.log_time_ns for m in log.messages(start_ns=300_000, stop_ns=310_000)]
    assert got == list(range(300_000, 310_000, 1_000))
    assert read_bytes < 4 * 100_000 + 10 * PAYLOAD  # a handful of 100 kB chunks
