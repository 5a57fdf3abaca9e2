"""A ROS 2 bag prefix read straight from a URL: its metadata.yaml, then each MCAP file by ranges.

The prefix's `metadata.yaml` is fetched (one request) and names the storage files; with
MCAP storage each file is a `RemoteMcapLog` (head, footer and summary: three requests a
file) and the files together are an `McapBag`, the local reader of ROS 2 MCAP folders:
the same merged summary, type registries and chunk-parallel read units across files
(runs of chunks, one ranged GET each, `logs.mcap.remote`). The bag's `fetch_stats` adds up
metadata.yaml's and every file's, so `remote_read` covers the whole bag.

What is not read by ranges (`RemoteUnindexedError`, for the caller to download the
prefix whole): SQLite storage (`.db3`: SQLite reads B-tree pages at offsets known only
once their parent page is read, a round trip per page; ranged page reads could work but
would cost thousands of requests per file, so the file is fetched whole, as a sequential
read it is cheap), and rosbag2's file or message compression (the local reader reads
those through rosbags, from files).
"""

from __future__ import annotations

from urllib.parse import urlsplit, urlunsplit

from syncaudit.config import parse_text
from syncaudit.errors import ConfigError, LogOpenError, SyncauditError
from syncaudit.logs.mcap.reader import McapLog
from syncaudit.logs.mcap.remote import RemoteMcapLog
from syncaudit.logs.ros2.mcap_storage import McapBag
from syncaudit.logs.ros2.metadata import MAX_METADATA_VALUES, parse_metadata
from syncaudit.logs.typesys import one_line
from syncaudit.remote.file import RemoteFile, RemoteUnindexedError
from syncaudit.remote.ranges import FetchStats
from syncaudit.remote.urls import UrlPath, public_url

METADATA_BYTES = 256 << 10
"""First read of metadata.yaml (a few KiB for most bags; read on if longer)."""
MAX_METADATA_BYTES = 64 << 20
SQLITE_REASON = (
    "SQLite storage reads its B-tree pages at offsets known only from their parent page "
    "(a request per page: ranged page reads are possible but not worth it), so the bag is "
    "downloaded whole"
)


def file_url(prefix: str, name: str) -> str:
    """The URL of `name` under a bag prefix, with the prefix's query string (a container's
    shared access signature covers its objects)."""
    parts = urlsplit(prefix)
    path = parts.path.rstrip("/")
    if path.endswith("/metadata.yaml"):
        path = path[: -len("/metadata.yaml")]
    return urlunsplit(parts._replace(path=f"{path}/{name}", fragment=""))


class RemoteMcapBag(McapBag):
    """A ROS 2 bag prefix with MCAP storage behind a URL (container 'rosbag2-mcap')."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.path = UrlPath(public_url(file_url(url, "")).rstrip("/"))
        self.warnings = []
        self._logs: list[McapLog] = []
        self._files: list[RemoteMcapLog] = []
        self._metadata = self._open_metadata()
        try:
            for name in self._storage_files():
                self._files.append(RemoteMcapLog(file_url(url, name)))
                self._logs.append(self._files[-1])
        except BaseException:
            for opened in self._files:
                opened.close()
            self._metadata.close()
            raise
        for log in self._files:
            for warning in log.warnings:
                self.warn(warning.code, warning.message)
        self.summary = self._merged_summary()

    def _open_metadata(self) -> RemoteFile:
        """The prefix's metadata.yaml, its first `METADATA_BYTES` fetched."""
        try:
            return RemoteFile.open(file_url(self.url, "metadata.yaml"), METADATA_BYTES)
        except LogOpenError as exc:
            raise LogOpenError(
                f"{self.path}: neither an .mcap/.bag file nor a ROS 2 bag prefix ({exc})"
            ) from None

    def _storage_files(self) -> list[str]:
        """The storage files metadata.yaml lists (MCAP storage, no rosbag2 compression)."""
        where = f"{self.path}/metadata.yaml"
        file = self._metadata
        size = file.size
        if size > MAX_METADATA_BYTES:
            raise LogOpenError(f"{where}: {size} bytes, more than any bag's metadata")
        head = min(size, METADATA_BYTES)
        file.hold(head, size)  # the rest of a long one, in one request
        data = b"".join(bytes(file.held(*span) or b"") for span in ((0, head), (head, size)))
        try:
            doc = parse_text(
                data.decode("utf-8"), "YAML", max_values=MAX_METADATA_VALUES
            )  # bounded like every config
        except (ConfigError, UnicodeDecodeError) as exc:
            raise LogOpenError(f"{where}: not a rosbag2 metadata file: {one_line(exc)}") from None
        meta = parse_metadata(self.path, doc, local=False)  # the local reader's rules
        self.warnings.extend(meta.warnings)
        storage, mode = meta.storage, meta.compression_mode
        if storage == "sqlite3":
            self._refuse(SQLITE_REASON)
        if mode:
            self._refuse(
                f"rosbag2 {mode} compression is read through rosbags from files, so the bag "
                "is downloaded whole"
            )
        return [file.name for file in meta.files]

    def _refuse(self, reason: str) -> None:
        raise RemoteUnindexedError(f"{self.path}: ROS 2 bag not read by ranges: {reason}", reason)

    @property
    def fetch_stats(self) -> FetchStats:
        """What reading this bag has fetched so far: metadata.yaml and every file (their
        workers too), against the files' sizes and needed chunks."""
        files = [log.fetch_stats for log in self._files]
        metadata = self._metadata.source.stats()
        return FetchStats(
            url=public_url(self.url),
            size_bytes=sum(f.size_bytes for f in files),
            fetched_bytes=metadata.fetched_bytes + sum(f.fetched_bytes for f in files),
            requests=metadata.requests + sum(f.requests for f in files),
            needed_chunk_bytes=sum(f.needed_chunk_bytes for f in files),
            chunks_fetched=sum(f.chunks_fetched for f in files),
            chunks_total=sum(f.chunks_total for f in files),
        )

    def _close(self) -> None:
        super()._close()
        self._metadata.close()


def open_remote_bag(url: str) -> McapBag:
    """A ROS 2 bag prefix URL, read by ranges where its storage allows."""
    try:
        return RemoteMcapBag(url)
    except SyncauditError:
        raise
    except Exception as exc:
        raise LogOpenError(
            f"{public_url(url)}: cannot read the ROS 2 bag: {one_line(exc)}"
        ) from exc
