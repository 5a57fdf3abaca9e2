"""Bad input: each case is one SyncauditError with its exit code and a one-line message naming
the path, never a traceback from a library; inputs keep their bytes and mtimes."""

from __future__ import annotations

import os
import shutil
import signal
import sqlite3
from collections.abc import Callable
from pathlib import Path

import pytest
import yaml

from syncaudit.errors import LogOpenError, LogReadError, SyncauditError
from syncaudit.logs import open_log

OUSTER_BAG = "ouster_os1_512x10/512x10_raw.bag"
VLP16_DIR = "velodyne_vlp16/1673400471837873222"
Untouched = Callable[[Path], Path]
Case = Callable[[Path, Callable[[], Path]], Path]
"""Builds the bad input in a tmp folder; the second argument gives the shared data folder."""


def _missing(tmp: Path, _data: Callable[[], Path]) -> Path:
    return tmp / "nope.mcap"


def _dir_without_metadata(tmp: Path, data: Callable[[], Path]) -> Path:
    folder = tmp / "bag"
    folder.mkdir()
    (folder / "bag_0.db3").write_bytes(b"SQLite format 3\x00" + bytes(100))
    return folder


def _empty(suffix: str) -> Case:
    def build(tmp: Path, _data: Callable[[], Path]) -> Path:
        path = tmp / f"empty{suffix}"
        path.write_bytes(b"")
        return path

    return build


def _random_bytes(tmp: Path, _data: Callable[[], Path]) -> Path:
    path = tmp / "noise.mcap"
    path.write_bytes(bytes((i * 7919 + 13) % 251 for i in range(4096)))
    return path


def _truncated_bag(fraction: float) -> Case:
    def build(tmp: Path, data: Callable[[], Path]) -> Path:
        raw = (data() / OUSTER_BAG).read_bytes()
        path = tmp / "cut.bag"
        path.write_bytes(raw[: int(len(raw) * fraction)])
        return path

    return build


def _damaged_bag_record(tmp: Path, data: Callable[[], Path]) -> Path:
    raw = bytearray((data() / OUSTER_BAG).read_bytes())
    at = raw.find(b"op=\x02", raw.find(b"op=\x02") + 1)  # the second message record header
    raw[at - 8 : at + 8] = bytes(b ^ 0xA5 for b in raw[at - 8 : at + 8])
    path = tmp / "damaged.bag"
    path.write_bytes(bytes(raw))
    return path


def _truncated_db3(tmp: Path, data: Callable[[], Path]) -> Path:
    (src,) = (data() / VLP16_DIR).glob("*.db3")
    raw = src.read_bytes()
    path = tmp / "cut.db3"
    path.write_bytes(raw[: len(raw) // 2])
    return path


def _sqlite_not_a_bag(tmp: Path, _data: Callable[[], Path]) -> Path:
    path = tmp / "other.db3"
    with sqlite3.connect(path) as db:
        db.execute("CREATE TABLE things (id INTEGER)")
    return path


def _metadata_case(edit: Callable[[Path, dict[str, object]], None]) -> Case:
    """A copy of the VLP-16 bag with its metadata.yaml changed by `edit`."""

    def build(tmp: Path, data: Callable[[], Path]) -> Path:
        bag = tmp / "bag"
        shutil.copytree(data() / VLP16_DIR, bag)
        for path in bag.iterdir():
            path.chmod(0o644)
        meta = yaml.safe_load((bag / "metadata.yaml").read_text())
        edit(bag, meta["rosbag2_bagfile_information"])
        (bag / "metadata.yaml").write_text(yaml.safe_dump(meta))
        return bag

    return build


def _yaml_garbage(tmp: Path, data: Callable[[], Path]) -> Path:
    bag = _metadata_case(lambda _b, _m: None)(tmp, data)
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: [unclosed\n  - : :\n")
    return bag


def _db3_missing(bag: Path, _meta: dict[str, object]) -> None:
    for path in bag.glob("*.db3"):
        path.unlink()


def _future_version(_bag: Path, meta: dict[str, object]) -> None:
    meta["version"] = 42


def _no_topics_key(_bag: Path, meta: dict[str, object]) -> None:
    del meta["topics_with_message_count"]


def _mcap_cut_in_header(tmp: Path, _data: Callable[[], Path]) -> Path:
    path = tmp / "header.mcap"
    path.write_bytes(b"\x89MCAP0\r\n\x01\x40\x00\x00\x00\x00\x00\x00\x00\x04\x00")
    return path


def _rosbag_v12(tmp: Path, _data: Callable[[], Path]) -> Path:
    path = tmp / "old.bag"
    path.write_bytes(b"#ROSBAG V1.2\n" + bytes(64))
    return path


def _fifo(tmp: Path, _data: Callable[[], Path]) -> Path:
    path = tmp / "pipe.mcap"
    os.mkfifo(path)
    return path


CASES: dict[str, tuple[Case, type[SyncauditError], str, bool]] = {
    # name: (builder, error, text in the message, needs the shared data)
    "missing-file": (_missing, LogOpenError, "no such file", False),
    "dir-without-metadata": (_dir_without_metadata, LogOpenError, "no metadata.yaml", False),
    "empty-mcap": (_empty(".mcap"), LogOpenError, "file is empty", False),
    "empty-bag": (_empty(".bag"), LogOpenError, "file is empty", False),
    "empty-db3": (_empty(".db3"), LogOpenError, "file is empty", False),
    "random-bytes": (_random_bytes, LogOpenError, "unknown log format", False),
    "mcap-cut-in-header": (_mcap_cut_in_header, LogOpenError, "header record", False),
    "rosbag-v1.2": (_rosbag_v12, LogOpenError, "version 1.2", False),
    "sqlite-not-a-bag": (_sqlite_not_a_bag, LogOpenError, "ROS 2 bag", False),
    "fifo": (_fifo, LogOpenError, "not a regular file", False),
    # cut anywhere later, a ROS 1 bag is read up to the cut (tests/logs/test_rosbag1.py)
    "bag-cut-in-bag-header": (_truncated_bag(0.01), LogReadError, "inside its bag header", True),
    "bag-damaged-record": (_damaged_bag_record, LogReadError, "ROS 1 chunk at byte 4109", True),
    # cut where no complete row is left: exit 3 (cuts that leave rows: tests/logs/test_sqlite.py)
    "db3-cut": (_truncated_db3, LogReadError, "no message can be read", True),
    "metadata-yaml-garbage": (_yaml_garbage, LogOpenError, "metadata", True),
    "metadata-db3-missing": (_metadata_case(_db3_missing), LogOpenError, "missing", True),
    "metadata-version-42": (_metadata_case(_future_version), LogOpenError, "version 42", True),
    "metadata-no-topics": (_metadata_case(_no_topics_key), LogOpenError, "topics_with", True),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_input_gives_one_line_error(
    case: str, tmp_path: Path, request: pytest.FixtureRequest, untouched: Untouched
) -> None:
    build, error, needle, needs_data = CASES[case]

    def data() -> Path:
        path: Path = request.getfixturevalue("lidar_data")
        return path

    if needs_data:
        data()  # skips when the shared recordings are absent
    path = build(tmp_path, data)
    if path.exists() and not path.is_fifo():
        untouched(path if path.is_dir() else path.parent)

    def hang(_signum: int, _frame: object) -> None:
        raise TimeoutError(f"open_log({path}) blocked")  # e.g. reading a FIFO

    previous = signal.signal(signal.SIGALRM, hang)
    signal.alarm(10)
    try:
        with pytest.raises(SyncauditError) as info, open_log(path) as log:
            for _ in log.messages():
                pass
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
    err = info.value
    assert type(err) is error, f"{type(err).__name__}: {err}"
    assert err.exit_code == error.exit_code
    text = str(err)
    assert "\n" not in text and text.startswith(str(path)), text
    assert needle in text, text


def test_real_recordings_are_never_modified(lidar_data: Path, untouched: Untouched) -> None:
    """Open and read every real recording in every form; bytes, mtimes and file sets stay."""
    untouched(lidar_data)
    paths = [lidar_data / OUSTER_BAG]
    for meta in sorted(lidar_data.glob("*/*/metadata.yaml")):
        paths += [meta.parent, *meta.parent.glob("*.db3")]
    for path in paths:
        with open_log(path) as log:
            for msg in log.messages():
                log.deserialize(msg)
