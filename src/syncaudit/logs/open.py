"""`open_log`: pick the backend for a path by its form and its magic bytes."""

from __future__ import annotations

from pathlib import Path

from syncaudit.errors import LogOpenError
from syncaudit.logs.base import LogReader
from syncaudit.logs.mcap_log import MAGIC as MCAP_MAGIC
from syncaudit.logs.mcap_log import McapLog
from syncaudit.logs.typesys import one_line

ROSBAG1_MAGIC = b"#ROSBAG V2.0"
ROSBAG_ANY_MAGIC = b"#ROSBAG V"
SQLITE_MAGIC = b"SQLite format 3\x00"

__all__ = ["MCAP_MAGIC", "ROSBAG1_MAGIC", "SQLITE_MAGIC", "open_log"]


def _rosbags_log(path: Path, ros1: bool) -> LogReader:
    """A bag through rosbags, imported only for bags (~40 ms an MCAP audit need not pay)."""
    from syncaudit.logs.rosbags_log import RosbagsLog

    return RosbagsLog(path, ros1=ros1)


def open_log(path: str | Path) -> LogReader:
    """Open an MCAP file, a ROS 2 bag (directory, `.db3`, `.mcap`) or a ROS 1 `.bag`.

    Files are opened read-only. Every failure is a LogOpenError (exit 2) or, for a file
    damaged past reading, a LogReadError (exit 3), with a one-line message naming the path.
    """
    path = Path(path)
    if not path.exists():
        raise LogOpenError(f"{path}: no such file or directory")
    if path.is_dir():
        if not (path / "metadata.yaml").is_file():
            raise LogOpenError(
                f"{path}: directory has no metadata.yaml, so it is not a ROS 2 bag "
                "(pass the .db3/.mcap file itself to read it without metadata)"
            )
        from syncaudit.logs.mcap_bag import mcap_storage_files, open_mcap_bag

        files = mcap_storage_files(path)  # MCAP storage: the chunk-parallel MCAP reader
        return open_mcap_bag(path, files) if files else _rosbags_log(path, ros1=False)
    if not path.is_file():
        raise LogOpenError(f"{path}: not a regular file or directory")
    try:
        with path.open("rb") as handle:
            head = handle.read(16)
    except OSError as exc:
        raise LogOpenError(f"{path}: cannot read: {one_line(exc)}") from exc
    if not head:
        raise LogOpenError(f"{path}: file is empty")
    if head.startswith(MCAP_MAGIC):
        return McapLog(path)
    if head.startswith(ROSBAG1_MAGIC):
        return _rosbags_log(path, ros1=True)
    if head.startswith(ROSBAG_ANY_MAGIC):
        version = head[len(ROSBAG_ANY_MAGIC) :].split(b"\n")[0].decode("ascii", "replace")
        raise LogOpenError(f"{path}: ROS 1 bag format version {version} is not supported (2.0 is)")
    if head.startswith(SQLITE_MAGIC):
        return _rosbags_log(path, ros1=False)
    raise LogOpenError(
        f"{path}: unknown log format (expected MCAP, ROS 2 .db3/.mcap, or ROS 1 .bag)"
    )
