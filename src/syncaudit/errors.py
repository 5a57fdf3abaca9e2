"""Errors of syncaudit, each mapped to one documented CLI exit code."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pydantic import ValidationError


class SyncauditError(Exception):
    """Base of every error syncaudit raises on purpose; carries the CLI exit code."""

    exit_code = 1


class LogOpenError(SyncauditError):
    """A log could not be opened: missing path, unknown container, no metadata."""

    exit_code = 2


class LogReadError(SyncauditError):
    """A log is corrupt or truncated beyond what can be read."""

    exit_code = 3


class UnknownTypeError(SyncauditError):
    """A message type has no definition in the log nor in `schemas/`."""

    exit_code = 4


class DecodeError(SyncauditError):
    """Vendor packet bytes do not match the layout they claim."""

    exit_code = 5


class ConfigError(SyncauditError):
    """A rig or analysis configuration is malformed or nonsensical."""

    exit_code = 6


class NoDataError(SyncauditError):
    """The log holds nothing the requested job can use (empty, missing topics)."""

    exit_code = 7


class OutputError(SyncauditError):
    """An output cannot be written: it exists (without --overwrite) or the folder is not writable."""

    exit_code = 8


class GateFailedError(SyncauditError):
    """An audit ran and its result crosses a configured threshold (CI gate)."""

    exit_code = 10


def validation_summary(exc: ValidationError) -> str:
    """A pydantic ValidationError on one line: `field.path: message (+N more)`."""
    errors = exc.errors()
    first = errors[0]
    where = ".".join(str(part) for part in first["loc"]) or "(top level)"
    message = " ".join(str(first["msg"]).split())
    more = f" (+{len(errors) - 1} more)" if len(errors) > 1 else ""
    return f"{where}: {message}{more}"
