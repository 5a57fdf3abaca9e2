"""Whether a saved calibration (`calib --json-out`) is of the log an audit reports on.

`calib --json-out` records the log it calibrated twice: its path (`log`) and its identity
(`log_identity`: size in bytes and a content fingerprint of sampled blocks, the fleet
gate's). An audit's `--calibration` is accepted when the fingerprints match (a copied or
moved log is the same log); a result without an identity (older files) is accepted only
for the same path. Anything else is refused unless the user says `--calibration-any-log`.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

IDENTITY_KEY = "log_identity"
"""The key of the calibration JSON holding the log's size and fingerprint."""


def log_identity(size_bytes: int | None, fingerprint: str) -> dict[str, Any]:
    """What `calib --json-out` stores of its log besides the path."""
    return {"size_bytes": size_bytes, "fingerprint": fingerprint}


def calibration_mismatch(
    document: Mapping[str, Any], log: str | Path, fingerprint: str | None
) -> str | None:
    """Why a calibration JSON is not of `log` (None when it is).

    `fingerprint` is the audited log's (None when it could not be read: the path decides).
    """
    named = str(document.get("log", ""))
    identity = document.get(IDENTITY_KEY)
    stored = identity.get("fingerprint") if isinstance(identity, Mapping) else None
    if isinstance(stored, str) and fingerprint is not None:
        if stored == fingerprint:
            return None
        return f"is the calibration of another log ({named}: its content differs from {log})"
    if _same_path(named, log):
        return None
    return f"is the calibration of {named}, not of {log} (it records no fingerprint to compare)"


def _same_path(named: str, log: str | Path) -> bool:
    if not named:
        return False
    if "://" in named or "://" in str(log):
        return named == str(log)
    try:
        return Path(named).resolve() == Path(log).resolve()
    except OSError:
        return False
