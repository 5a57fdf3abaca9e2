"""A small file kept beside a remote log (its rig, `LOG.rig.yaml`), read in one request.

A local log's rig is found by looking beside it; a remote one's by asking for the object
whose path is the log's with a suffix added (the query string kept: a container's shared
access signature covers its objects). No such object is the common case and costs one
request; a refusal (HTTP 401/403: a URL signed for the log alone, or S3 hiding a missing
key) is said, not an error; anything else (the server failing) is an error, since the
audit would silently run on another rig.
"""

from __future__ import annotations

from dataclasses import dataclass
from urllib.parse import urlsplit, urlunsplit

from syncaudit.errors import LogOpenError, LogReadError
from syncaudit.remote.ranges import RefusedReadError, open_object, read_head
from syncaudit.remote.urls import public_url

MAX_SIDECAR_BYTES = 1 << 20
"""Largest file read beside a log (as `config.MAX_CONFIG_BYTES`: a rig is a few KiB)."""


@dataclass(frozen=True, slots=True)
class Sidecar:
    """What was found at `url`: its bytes, or None with why (None: there is no such object)."""

    url: str
    data: bytes | None
    refused: str | None = None

    @property
    def name(self) -> str:
        """The URL as messages show it (no query string, no user info)."""
        return public_url(self.url)


def beside(url: str, suffix: str) -> str:
    """`url` with `suffix` appended to its path, query kept (`.../a.mcap` -> `.../a.mcap.rig.yaml`)."""
    parts = urlsplit(url)
    return urlunsplit(parts._replace(path=parts.path.rstrip("/") + suffix, fragment=""))


def read_small(url: str, max_bytes: int = MAX_SIDECAR_BYTES) -> Sidecar:
    """The object at `url` whole, if it exists and has at most `max_bytes` bytes (read as
    every remote range is, `ranges.read_head`: retried where a retry can help).

    Raises:
        LogReadError: the object is larger than `max_bytes`, or the read failed otherwise
            than by its absence or a refusal.
    """
    try:
        data, size = read_head(open_object(url), max_bytes + 1, None)
    except LogOpenError:  # no such object
        return Sidecar(url, None)
    except RefusedReadError as exc:
        return Sidecar(url, None, refused=exc.reason or "refused")
    if size > max_bytes:
        raise LogReadError(f"{public_url(url)}: {size} bytes, more than {max_bytes}")
    return Sidecar(url, data)
