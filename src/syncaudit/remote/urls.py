"""URL helpers: which arguments are remote logs, the fsspec filesystem of a URL, and the
form of a URL that messages may show (no query string, no user info)."""

from __future__ import annotations

import re
from pathlib import PosixPath
from typing import Any
from urllib.parse import urlsplit

from syncaudit.errors import UsageError

URL = re.compile(r"^(s3|s3a|gs|gcs|az|abfs|abfss|http|https)://", re.IGNORECASE)
EXTRAS = {"s3": "s3", "s3a": "s3", "gs": "gcs", "gcs": "gcs", "az": "azure", "abfs": "azure"}
"""URL scheme -> the syncaudit extra that installs its fsspec backend (else 'http')."""


def is_url(item: str) -> bool:
    """True for the object-storage and HTTP URLs fsspec reads."""
    return bool(URL.match(item))


def public_url(url: str) -> str:
    """The URL without query string, fragment or user info (no credentials, no tokens)."""
    parts = urlsplit(url)
    host = parts.hostname or ""
    if parts.port:
        host = f"{host}:{parts.port}"
    return f"{parts.scheme}://{host}{parts.path}"


def filesystem(url: str) -> tuple[Any, str]:
    """(fsspec filesystem, path) for a URL; a missing backend names the extra to install."""
    scheme = url.split("://", 1)[0].lower()
    extra = EXTRAS.get(scheme, "http")
    try:
        from fsspec.core import url_to_fs  # type: ignore[import-untyped]
    except ImportError:
        raise UsageError(f"reading {scheme}:// needs pip install 'syncaudit[{extra}]'") from None
    try:
        fs, path = url_to_fs(url)
    except ImportError:
        raise UsageError(f"reading {scheme}:// needs pip install 'syncaudit[{extra}]'") from None
    return fs, path


class UrlPath(PosixPath):
    """A URL where a reader keeps a path: `str()` gives the URL back (scheme://host/path),
    so every message it writes names the log by its URL."""

    def __str__(self) -> str:
        parts = self.parts
        return f"{parts[0]}//{'/'.join(parts[1:])}" if parts else ""
