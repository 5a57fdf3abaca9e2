"""`open_log`: pick the backend for a path by its form and its magic bytes."""

from __future__ import annotations

from pathlib import Path
from urllib.parse import urlsplit

from syncaudit.errors import LogOpenError
from syncaudit.logs.base import LogReader
from syncaudit.logs.magic import (
    MCAP_MAGIC,
    PCAP_MAGICS,
    PCAPNG_MAGIC,
    ROSBAG1_MAGIC,
    ROSBAG_ANY_MAGIC,
    SQLITE_MAGIC,
)
from syncaudit.logs.typesys import one_line
from syncaudit.remote.urls import public_url

__all__ = ["MCAP_MAGIC", "ROSBAG1_MAGIC", "SQLITE_MAGIC", "open_log"]


def _rosbags_log(path: Path, ros1: bool) -> LogReader:
    """A bag through rosbags, imported only for bags (~40 ms an MCAP audit need not pay)."""
    from syncaudit.logs.rosbags_reader import RosbagsLog

    return RosbagsLog(path, ros1=ros1)


def _bag_folder(path: Path) -> LogReader:
    """A rosbag2 folder: its metadata.yaml read here (quirks resolved), then by storage."""
    from syncaudit.logs.ros2.metadata import read_metadata

    meta = read_metadata(path)
    if meta.storage == "sqlite3":
        from syncaudit.logs.ros2.sqlite_reader import open_sqlite_log

        return open_sqlite_log(path, meta)
    if not meta.compression_mode:
        from syncaudit.logs.ros2.mcap_storage import open_mcap_bag

        log = open_mcap_bag(path, meta.files)  # chunk-parallel, across every file
        for warning in meta.warnings:
            log.warn(warning.code, warning.message)
        return log
    # rosbag2's file/message compression modes: rosbags reads the bag, but refuses one with
    # a blank storage_identifier or serialization_format.
    if meta.warnings:
        raise LogOpenError(
            f"{path}: metadata.yaml has blank fields ({meta.warnings[0].message}) and "
            f"the bag is split into {len(meta.files)} files or compressed; pass its "
            ".mcap files one by one"
        )
    return _rosbags_log(path, ros1=False)


def _remote_log(url: str) -> LogReader:
    """A log behind a URL, read by ranges: an indexed MCAP file, a ROS 1 bag, or a ROS 2 bag
    prefix with MCAP storage (any other URL: the prefix of a bag, its metadata.yaml read
    first). What cannot be read by ranges raises `RemoteUnindexedError`, for the caller
    (the fleet gate) to download the log whole."""
    path = urlsplit(url).path.lower()
    if path.endswith(".mcap"):
        from syncaudit.logs.mcap.remote import RemoteMcapLog

        return RemoteMcapLog(url)
    if path.endswith(".bag"):
        from syncaudit.logs.ros1.remote import RemoteRosbag1Log

        return RemoteRosbag1Log(url)
    from syncaudit.logs.ros2.remote import SQLITE_REASON, open_remote_bag

    if path.endswith(".db3"):
        from syncaudit.remote.file import RemoteUnindexedError

        message = f"{public_url(url)}: not read by ranges: {SQLITE_REASON}"
        raise RemoteUnindexedError(message, SQLITE_REASON)
    return open_remote_bag(url)


def open_log(
    path: str | Path,
    *,
    lidar_metadata: str | Path | None = None,
    lidar_capture: str | Path | None = None,
) -> LogReader:
    """Open an MCAP file, a ROS 2 bag (directory, `.db3`, `.mcap`), a ROS 1 `.bag`, or a
    `.pcap` / `.pcapng` capture of LiDAR traffic (`lidar_metadata`: the Ouster sensor
    metadata JSON for it, by default the `.json` of the same stem beside it).

    `lidar_capture`: a capture recorded beside the log on the same host, whose LiDAR
    streams join the log's topics (`logs.combined`).

    Files are opened read-only. Every failure is a LogOpenError (exit 2) or, for a file
    damaged past reading, a LogReadError (exit 3), with a one-line message naming the path.
    An indexed MCAP or ROS 1 bag may also be a URL (http(s)://, or s3:// etc. via fsspec).
    """
    if lidar_capture is not None:
        from syncaudit.logs.combined import CombinedLog

        main = open_log(path)
        try:
            return CombinedLog(main, open_log(lidar_capture, lidar_metadata=lidar_metadata))
        except BaseException:
            main.close()
            raise
    if isinstance(path, str) and "://" in path:
        return _remote_log(path)
    path = Path(path)
    if not path.exists():
        raise LogOpenError(f"{path}: no such file or directory")
    if path.is_dir():
        if not (path / "metadata.yaml").is_file():
            raise LogOpenError(
                f"{path}: directory has no metadata.yaml, so it is not a ROS 2 bag "
                "(pass the .db3/.mcap file itself to read it without metadata)"
            )
        return _bag_folder(path)
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
        from syncaudit.logs.mcap.reader import McapLog

        return McapLog(path)
    if head.startswith(ROSBAG1_MAGIC):
        from syncaudit.logs.ros1.reader import Rosbag1Log

        return Rosbag1Log(path)
    if head.startswith(ROSBAG_ANY_MAGIC):
        version = head[len(ROSBAG_ANY_MAGIC) :].split(b"\n")[0].decode("ascii", "replace")
        raise LogOpenError(f"{path}: ROS 1 bag format version {version} is not supported (2.0 is)")
    if head[:4] in PCAP_MAGICS or head.startswith(PCAPNG_MAGIC):
        from syncaudit.logs.pcap.reader import PcapLog

        return PcapLog(path, None if lidar_metadata is None else Path(lidar_metadata))
    if head.startswith(SQLITE_MAGIC):
        from syncaudit.logs.ros2.sqlite_reader import open_sqlite_log

        return open_sqlite_log(path)
    raise LogOpenError(
        f"{path}: unknown log format (expected MCAP, ROS 2 .db3/.mcap, ROS 1 .bag, or a "
        ".pcap/.pcapng capture)"
    )
