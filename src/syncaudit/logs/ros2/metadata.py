"""rosbag2 `metadata.yaml`: its files, storage, compression and topics, with real-world quirks.

Versions 1-9 of the format (rosbag2's `rosbag2_bagfile_information`). Quirks of bags written
by other tools that `ros2 bag` reads and this module accepts with a warning:

- `storage_identifier: ""` (some rosbag2 versions): the storage is inferred from the files'
  magic bytes (SQLite or MCAP) or, failing that, their extension;
- a topic's `serialization_format: ""`: rosbag2 only ever writes CDR, so it is read as cdr.

A serialization format other than cdr (`protobuf`, `json`, ...) is kept as it is on the
topic: the reader reports it truthfully and the audit decides what it can read.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path, PurePath
from typing import Any

from syncaudit.config import parse_text, read_text
from syncaudit.errors import ConfigError, LogOpenError
from syncaudit.logs.magic import MCAP_MAGIC, SQLITE_MAGIC, ZSTD_MAGIC
from syncaudit.logs.model import LogWarning
from syncaudit.logs.typesys import one_line

STORAGES = ("sqlite3", "mcap")
MAX_VERSION = 9


@dataclass(frozen=True, slots=True)
class TopicMeta:
    """A topic as metadata.yaml lists it."""

    name: str
    msgtype: str
    serialization_format: str
    message_count: int


@dataclass(slots=True)
class BagMetadata:
    """What metadata.yaml says of a bag folder, quirks already resolved."""

    folder: Path
    version: int
    storage: str
    """'sqlite3' or 'mcap'."""
    files: list[Path]
    compression_mode: str
    """'' (none), 'message' or 'file'."""
    compression_format: str
    message_count: int
    start_ns: int | None
    end_ns: int | None
    topics: list[TopicMeta]
    warnings: list[LogWarning] = field(default_factory=list)


def sniff_storage(path: Path) -> str | None:
    """'sqlite3' or 'mcap' from a file's magic (through a zstd file frame) or extension."""
    try:
        with path.open("rb") as handle:
            head = handle.read(64)
    except OSError:
        head = b""
    if head.startswith(ZSTD_MAGIC):
        import zstandard

        try:
            head = zstandard.ZstdDecompressor().decompressobj().decompress(head)
        except zstandard.ZstdError:
            head = b""
    if head.startswith(SQLITE_MAGIC):
        return "sqlite3"
    if head.startswith(MCAP_MAGIC):
        return "mcap"
    return storage_by_name(path)


def storage_by_name(path: PurePath) -> str | None:
    """'sqlite3' or 'mcap' from a storage file's extension (past a `.zstd`), else None."""
    suffixes = [s for s in path.suffixes if s != ".zstd"]
    if suffixes and suffixes[-1] == ".db3":
        return "sqlite3"
    if suffixes and suffixes[-1] == ".mcap":
        return "mcap"
    return None


MAX_METADATA_BYTES = 64 << 20
"""Largest metadata.yaml read (64 MiB, as for a bag read from a URL)."""

MAX_METADATA_VALUES = 50_000
"""Most values in a metadata.yaml once aliases expand: a bag of 1,000 split files holds about
7,000 (each file about 7 values), so this admits about 7,000 files. Composing YAML costs 8-30
us a value here (100,000 took 3.1 s in the fuzz campaign), so a hostile one costs < 1.5 s."""


def read_metadata(folder: Path) -> BagMetadata:
    """Parse `folder/metadata.yaml`; LogOpenError (one line naming the file) where unusable."""
    where = folder / "metadata.yaml"
    try:
        text = read_text(where, what="metadata.yaml", max_bytes=MAX_METADATA_BYTES)
    except ConfigError as exc:
        raise LogOpenError(str(exc)) from None
    try:
        # config's bounded YAML parser (libyaml where installed; aliases, depth and
        # duplicate keys bounded as in every config file)
        doc = parse_text(text, "YAML", max_values=MAX_METADATA_VALUES)
    except ConfigError as exc:
        raise LogOpenError(f"{folder}: metadata.yaml is {_why(exc)}") from None
    return parse_metadata(folder, doc)


def parse_metadata(folder: Path, doc: Any, *, local: bool = True) -> BagMetadata:
    """A parsed metadata.yaml of the bag at `folder`; LogOpenError (one line) where unusable.

    `local`: the storage files are checked on disk and a blank storage is read from their
    magic bytes; otherwise (a bag prefix behind a URL) it is read from their names.
    """
    try:
        return _parse(folder, doc, local)
    except LogOpenError:
        raise
    except KeyError as exc:
        raise LogOpenError(f"{folder}: metadata.yaml has no key {exc}") from None
    except (TypeError, ValueError, AttributeError) as exc:
        raise LogOpenError(f"{folder}: metadata.yaml has a bad value: {one_line(exc)}") from None


def _why(exc: ConfigError) -> str:
    """A bounded parser's refusal worded after 'metadata.yaml is'."""
    message = str(exc)
    return message if message.startswith("not valid") else f"refused: {message}"


def _int(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"{name} is {value!r}, not an integer")
    return value


def _str(value: Any) -> str:
    return "" if value is None else str(value)


def _parse(folder: Path, doc: Any, local: bool) -> BagMetadata:
    if not isinstance(doc, dict) or not isinstance(
        info := doc.get("rosbag2_bagfile_information"), dict
    ):
        raise LogOpenError(f"{folder}: metadata.yaml has no rosbag2_bagfile_information mapping")
    version = _int(info["version"], "version")
    if version > MAX_VERSION:
        raise LogOpenError(
            f"{folder}: rosbag2 metadata version {version} is newer than this tool reads "
            f"(1-{MAX_VERSION})"
        )
    warnings: list[LogWarning] = []
    files = [folder / PurePath(str(x)).name for x in info["relative_file_paths"]]
    missing = [p.name for p in files if local and not p.is_file()]
    if missing:
        raise LogOpenError(
            f"{folder}: storage files listed in metadata.yaml are missing: {missing}"
        )
    if not files:
        raise LogOpenError(f"{folder}: metadata.yaml lists no storage files")
    storage = _str(info["storage_identifier"])
    if storage not in STORAGES:
        found = {sniff_storage(p) if local else storage_by_name(p) for p in files}
        if len(found) != 1 or None in found:
            raise LogOpenError(
                f"{folder}: metadata.yaml names storage {storage!r} and the files do not tell "
                "(expected SQLite .db3 or MCAP files)"
            )
        inferred = str(found.pop())
        how = "their magic bytes" if local else "their names"
        warnings.append(
            LogWarning(
                "rosbag2-storage-inferred",
                f"{folder}: metadata.yaml names storage {storage!r}; the files are {inferred} "
                f"(read by {how})",
            )
        )
        storage = inferred
    mode = _str(info.get("compression_mode")).lower()
    mode = "" if mode == "none" else mode
    fmt = _str(info.get("compression_format")).lower()
    if mode not in ("", "message", "file"):
        raise LogOpenError(f"{folder}: metadata.yaml compression_mode {mode!r} is not known")
    if mode and fmt != "zstd":
        raise LogOpenError(
            f"{folder}: compression format {fmt!r} is not supported (rosbag2 writes zstd)"
        )
    topics: list[TopicMeta] = []
    for entry in info["topics_with_message_count"] or []:
        meta = entry["topic_metadata"]
        fmt_topic = _str(meta.get("serialization_format"))
        if not fmt_topic:
            warnings.append(
                LogWarning(
                    "rosbag2-empty-serialization",
                    f"{folder}: topic {meta['name']} has an empty serialization_format in "
                    "metadata.yaml; read as cdr (the only format rosbag2 writes)",
                )
            )
            fmt_topic = "cdr"
        topics.append(
            TopicMeta(
                name=str(meta["name"]),
                msgtype=str(meta["type"]),
                serialization_format=fmt_topic,
                message_count=_int(entry.get("message_count", 0), "message_count"),
            )
        )
    count = _int(info.get("message_count", 0), "message_count")
    start = _int(info["starting_time"]["nanoseconds_since_epoch"], "starting_time")
    duration = _int(info["duration"]["nanoseconds"], "duration")
    return BagMetadata(
        folder=folder,
        version=version,
        storage=storage,
        files=files,
        compression_mode=mode,
        compression_format=fmt,
        message_count=count,
        start_ns=start if count else None,
        end_ns=start + duration if count else None,
        topics=topics,
        warnings=warnings,
    )
