"""The mark every output of this tool carries, and the check `--overwrite` makes before replacing.

`--overwrite` replaces only what this tool wrote; anything else is refused whatever the
flags. Each format carries the mark where its readers ignore it (docs/outputs.md):

- MCAP: the Header record's `library` is `syncaudit`;
- ROS 2 bag folder: `custom_data` of `metadata.yaml` holds `syncaudit.written_by`, and the
  folder holds nothing but the bag's files;
- ROS 1 bag: the bag header record's padding starts with `syncaudit <version>`;
- Parquet: the footer's key-value metadata has a `syncaudit` key;
- HTML: a `generator` meta tag in the head; JSON: a first `written_by` key; YAML, TOML:
  a first comment line; Markdown, XML: a first comment (after the XML declaration);
- CSV (no room for a mark): a sidecar `.NAME.syncaudit` holding the SHA-256 of the bytes
  written; a CSV changed since is no longer the tool's.

`refusal(path)` says why an existing target is not the tool's (None when it is).
"""

from __future__ import annotations

import hashlib
import re
import struct
from pathlib import Path

from syncaudit import __version__

WRITTEN_BY = f"syncaudit {__version__}"
"""The mark's text (tool and version)."""
BAG2_KEY = "syncaudit.written_by"
"""The `custom_data` key of a ROS 2 bag's `metadata.yaml`."""
SIDECAR_SUFFIXES = (".csv",)
"""Single files with no room for a mark: their mark is a sidecar."""

_TEXT_MARK = re.compile(
    rb'\A(?:\{\s*"written_by": "syncaudit '
    rb"|# written by syncaudit "
    rb"|<!-- written by syncaudit "
    rb"|<\?xml[^>]{0,200}\?>\s*<!-- written by syncaudit "
    rb"|<!doctype html>[^>]{0,100}>(?:<[^>]{0,100}>){0,4}"
    rb'<meta name="generator" content="written by syncaudit )',
    re.IGNORECASE,
)
"""The text marks, where the tool puts them: at the very start (a JSON document's first
key, a first comment line) or in an HTML page's head; a document that merely mentions
the phrase (this tool's own docs) is not one of its outputs."""
_HEAD_BYTES = 4096
_MCAP_MAGIC = b"\x89MCAP0\r\n"
_BAG1_MAGIC = b"#ROSBAG V2.0\n"
_PARQUET_MAGIC = b"PAR1"
_SQLITE_MAGIC = b"SQLite format 3\x00"
_BAG2_FILES = (".db3", ".db3-shm", ".db3-wal", ".mcap", ".yaml")
_MAX_METADATA_BYTES = 4 * 1024 * 1024
_MAX_FOOTER_BYTES = 64 * 1024 * 1024


def sidecar_of(path: Path) -> Path:
    """The sidecar holding the mark of a file that cannot carry one (`.NAME.syncaudit`)."""
    return path.with_name(f".{path.name}.syncaudit")


def sidecar_text(data: bytes) -> str:
    """What a sidecar holds for `data`: the mark and the SHA-256 of the bytes written."""
    return f"{WRITTEN_BY}\nsha256 {hashlib.sha256(data).hexdigest()}\n"


def refusal(path: Path) -> str | None:
    """Why the existing `path` is not an output of this tool; None when it carries the mark."""
    if path.is_symlink():
        return "is a symbolic link (not an output of syncaudit)"
    if path.is_dir():
        return _folder_refusal(path)
    try:
        with path.open("rb") as handle:
            head = handle.read(_HEAD_BYTES)
    except OSError as exc:
        return f"cannot be read to check who wrote it ({exc.strerror or exc})"
    if head.startswith(_MCAP_MAGIC):
        return (
            None if _mcap_library(head) == "syncaudit" else "is an MCAP log syncaudit did not write"
        )
    if head.startswith(_BAG1_MAGIC):
        return None if _bag1_marked(head) else "is a ROS 1 bag syncaudit did not write"
    if head.startswith(_PARQUET_MAGIC):
        return None if _parquet_marked(path) else "is a Parquet file syncaudit did not write"
    if head.startswith(_SQLITE_MAGIC):
        return "is an SQLite database (a ROS 2 recording?) syncaudit did not write"
    if path.suffix.lower() in SIDECAR_SUFFIXES:
        return _sidecar_refusal(path)
    if _TEXT_MARK.search(head):
        return None
    if not head:
        return "is an empty file syncaudit did not write"
    return "is a file syncaudit did not write (it carries no syncaudit mark)"


def _folder_refusal(path: Path) -> str | None:
    try:
        entries = list(path.iterdir())
    except OSError as exc:
        return f"is a folder that cannot be read ({exc.strerror or exc})"
    metadata = path / "metadata.yaml"
    if not metadata.is_file():
        return "is an existing folder that is not a log syncaudit wrote"
    if not all(e.is_file() and e.name.endswith(_BAG2_FILES) for e in entries):
        return "is a folder holding files other than a bag's; not a log syncaudit wrote"
    if not _bag2_marked(metadata):
        return "is a ROS 2 bag syncaudit did not write (a recording?)"
    return None


def _bag2_marked(metadata: Path) -> bool:
    """Whether a `metadata.yaml` names this tool in its `custom_data`."""
    import yaml

    try:
        if metadata.stat().st_size > _MAX_METADATA_BYTES:
            return False
        info = yaml.safe_load(metadata.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return False
    if not isinstance(info, dict):
        return False
    body = info.get("rosbag2_bagfile_information")
    custom = body.get("custom_data") if isinstance(body, dict) else None
    value = custom.get(BAG2_KEY) if isinstance(custom, dict) else None
    return isinstance(value, str) and value.startswith("syncaudit")


def _mcap_library(head: bytes) -> str | None:
    """The `library` of an MCAP's Header record (opcode 1: profile, library strings)."""
    start = len(_MCAP_MAGIC)
    try:
        if head[start] != 0x01:
            return None
        pos = start + 9
        (profile_len,) = struct.unpack_from("<I", head, pos)
        pos += 4 + profile_len
        (library_len,) = struct.unpack_from("<I", head, pos)
        library = head[pos + 4 : pos + 4 + library_len]
    except (IndexError, struct.error):
        return None
    return library.decode("utf-8", "replace")


def bag1_data_span(head: bytes) -> tuple[int, int] | None:
    """(offset, length) of the bag header record's data (its padding) in a ROS 1 bag."""
    pos = len(_BAG1_MAGIC)
    try:
        (header_len,) = struct.unpack_from("<I", head, pos)
        pos += 4 + header_len
        (data_len,) = struct.unpack_from("<I", head, pos)
    except struct.error:
        return None
    return pos + 4, data_len


def _bag1_marked(head: bytes) -> bool:
    span = bag1_data_span(head)
    if span is None:
        return False
    offset, length = span
    return head[offset : offset + min(length, 64)].startswith(b"syncaudit")


def _parquet_marked(path: Path) -> bool:
    """Whether a Parquet footer's key-value metadata holds the `syncaudit` key."""
    try:
        with path.open("rb") as handle:
            handle.seek(0, 2)
            size = handle.tell()
            if size < 12:
                return False
            handle.seek(size - 8)
            tail = handle.read(8)
            (footer_len,) = struct.unpack("<I", tail[:4])
            if tail[4:] != _PARQUET_MAGIC or footer_len > min(size - 12, _MAX_FOOTER_BYTES):
                return False
            handle.seek(size - 8 - footer_len)
            footer = handle.read(footer_len)
    except OSError:
        return False
    # Thrift compact strings are stored as their raw bytes after a length varint.
    return b"\x09syncaudit" in footer


def _sidecar_refusal(path: Path) -> str | None:
    sidecar = sidecar_of(path)
    try:
        recorded = sidecar.read_text(encoding="utf-8")
        data = path.read_bytes()
    except (OSError, UnicodeDecodeError):
        return f"is a file syncaudit did not write (no {sidecar.name} beside it)"
    expected = f"sha256 {hashlib.sha256(data).hexdigest()}"
    if not recorded.startswith("syncaudit ") or expected not in recorded.splitlines():
        return f"has changed since syncaudit wrote it ({sidecar.name} no longer matches)"
    return None


HTML_MARK = f'<meta name="generator" content="written by {WRITTEN_BY}">'
"""The mark of every HTML page (in its head)."""
COMMENT_MARK = f"# written by {WRITTEN_BY}\n"
"""The mark of YAML and TOML outputs (a first comment line)."""
MARKUP_MARK = f"<!-- written by {WRITTEN_BY} -->\n"
"""The mark of Markdown outputs (a first comment line)."""
JSON_KEY = "written_by"
"""The first key of every JSON document written to a file."""


def marked_json(data: object) -> object:
    """`data` with the mark as its first key when it is a JSON object (else as given)."""
    if isinstance(data, dict):
        return {JSON_KEY: WRITTEN_BY, **{k: v for k, v in data.items() if k != JSON_KEY}}
    return data


def mark_bag1(path: Path) -> None:
    """Write the mark into the padding of a ROS 1 bag's header record (readers skip it)."""
    mark = WRITTEN_BY.encode()
    with path.open("r+b") as handle:
        head = handle.read(_HEAD_BYTES)
        span = bag1_data_span(head) if head.startswith(_BAG1_MAGIC) else None
        if span is None or span[1] < len(mark):
            raise OSError(f"{path}: no bag header padding to mark")
        handle.seek(span[0])
        handle.write(mark)
