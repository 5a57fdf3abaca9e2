"""Logs under a URL prefix, and a cheap fingerprint of a remote log (no data read)."""

from __future__ import annotations

import hashlib
from typing import Any
from urllib.parse import urlsplit

from syncaudit.errors import LogOpenError
from syncaudit.remote.urls import filesystem, public_url

LOG_SUFFIXES = (".mcap", ".bag")


def _url(fs: Any, path: str) -> str:
    return path if "://" in path else str(fs.unstrip_protocol(path))


def list_logs(url: str) -> list[str]:
    """The logs a URL names: itself (a log file or a ROS 2 bag prefix) or those under it.

    Under a prefix: every .mcap/.bag object, and every folder holding a metadata.yaml
    (a ROS 2 bag: its storage files are not logs of their own), sorted.
    """
    if urlsplit(url).path.endswith(LOG_SUFFIXES):
        return [url]
    fs, path = filesystem(url)
    root = path.rstrip("/")
    try:
        files = [str(f) for f in fs.find(root)]
    except FileNotFoundError:
        return []
    except Exception as exc:
        raise LogOpenError(f"{public_url(url)}: cannot list: {exc}".splitlines()[0]) from None
    bags = sorted({f.rsplit("/", 1)[0] for f in files if f.endswith("/metadata.yaml")})
    if root in bags or f"{root}/metadata.yaml" in files:
        return [url]
    logs = [
        f
        for f in files
        if f.endswith(LOG_SUFFIXES) and not any(f.startswith(b + "/") for b in bags)
    ]
    return sorted(_url(fs, p) for p in logs + bags)


def remote_fingerprint(url: str) -> str:
    """Size and the store's version tag (ETag, generation, mtime) of each object of a log."""
    fs, path = filesystem(url)
    digest = hashlib.blake2b(digest_size=16)
    try:
        info = fs.info(path)
        infos = [info]
        if info.get("type") == "directory":
            infos = [fs.info(f) for f in sorted(fs.find(path))]
    except FileNotFoundError:
        raise LogOpenError(f"{public_url(url)}: no such log") from None
    except Exception as exc:
        raise LogOpenError(f"{public_url(url)}: cannot open: {exc}".splitlines()[0]) from None
    for item in infos:
        tag = next(
            (
                str(item[k])
                for k in ("ETag", "etag", "generation", "LastModified", "last_modified", "mtime")
                if item.get(k)
            ),
            "",
        )
        name = str(item.get("name", "")).split("?", 1)[0]
        digest.update(f"{name.rsplit('/', 1)[-1]}:{item.get('size')}:{tag}".encode())
    return digest.hexdigest()
