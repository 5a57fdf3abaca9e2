"""Errors of syncaudit, each mapped to one documented CLI exit code.

This module holds the project's one exit-code table (`EXIT_CODES`); the README prints the
same table, and a test keeps the two equal.
"""

from __future__ import annotations

EXIT_OK = 0
EXIT_USAGE = 64
"""A usage error: unknown option, bad option value, conflicting options (BSD's EX_USAGE)."""
EXIT_INTERNAL = 70
"""A bug: anything not raised on purpose (BSD's EX_SOFTWARE)."""
EXIT_INTERRUPTED = 130
"""SIGINT or SIGTERM (128 + SIGINT, as shells report an interrupted command)."""


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


class ConfigError(SyncauditError, ValueError):
    """A rig or analysis configuration is malformed or nonsensical.

    Also a ValueError, as pydantic's ValidationError is: code that validated a config and
    caught ValueError keeps working now that every config model raises ConfigError.
    A validation failure also says where (`key_path`, e.g. `("cameras", 0, "stamp")`) and
    what (`detail`), so a command can name the option that set the key instead.
    """

    exit_code = 6

    def __init__(
        self, message: str, *, key_path: tuple[str | int, ...] = (), detail: str | None = None
    ) -> None:
        super().__init__(message)
        self.key_path = key_path
        self.detail = detail


class NoDataError(SyncauditError):
    """The log holds nothing the requested job can use (empty, missing topics)."""

    exit_code = 7


class OutputError(SyncauditError):
    """An output cannot be written: it exists without --overwrite, no permission, disk full."""

    exit_code = 8


class GateFailedError(SyncauditError):
    """An audit ran and its result crosses a configured threshold (CI gate)."""

    exit_code = 10


class UsageError(SyncauditError):
    """The command line itself is wrong: an unknown option, a bad value, conflicting options."""

    exit_code = EXIT_USAGE


class InputOpenError(SyncauditError):
    """An input that is not a log (rig, config, policy, manifest, results database) cannot
    be opened: missing, a directory, no permission. Exit 2, as a log that cannot be opened;
    a file that opens but holds nonsense is a ConfigError (6)."""

    exit_code = LogOpenError.exit_code


class MissingExtraError(UsageError):
    """An option needs an optional extra that is not installed (`--parquet` without
    pyarrow, `calib` without small_gicp/gtsam): a usage error, exit 64, naming the extra."""


class WorkerDiedError(SyncauditError):
    """A worker process reading the log died under the run (killed, or crashed).

    Killed from outside (the kernel's OOM killer, `kill -9`): neither the log's fault nor
    a bug, the run was stopped like an interrupt, so exit 130; a crash (a fatal signal
    such as SIGSEGV, or an exit status) is a bug of ours or of a library, exit 70.
    """

    exit_code = EXIT_INTERRUPTED

    def __init__(self, message: str, *, exit_code: int = EXIT_INTERRUPTED) -> None:
        super().__init__(message)
        self.exit_code = exit_code


class Interrupted(BaseException):
    """SIGTERM turned into an exception in the main process, so outputs are rolled back."""


EXIT_CODES: tuple[tuple[int, str], ...] = (
    (EXIT_OK, "done"),
    (
        LogOpenError.exit_code,
        "the log, or another input (rig, config, database), cannot be opened (missing, empty, unknown format, directory without metadata)",
    ),
    (
        LogReadError.exit_code,
        "the log is damaged beyond reading (in `gate`: some log could not be read)",
    ),
    (
        UnknownTypeError.exit_code,
        "a needed message type or encoding has no definition or cannot be read",
    ),
    (DecodeError.exit_code, "vendor packet bytes do not match their layout"),
    (
        ConfigError.exit_code,
        "a config file (rig, calib config, policy) is malformed or nonsensical",
    ),
    (NoDataError.exit_code, "the log holds nothing to audit (empty, missing topics)"),
    (
        OutputError.exit_code,
        "an output cannot be written (exists without `--overwrite`, no permission, disk full, is a directory)",
    ),
    (
        GateFailedError.exit_code,
        "`--gate`: a threshold or policy check failed, or something required was not judged",
    ),
    (
        EXIT_USAGE,
        "usage error: unknown option, bad option value, conflicting options, an option's extra not installed",
    ),
    (EXIT_INTERNAL, "internal error (a bug; `SYNCAUDIT_DEBUG=1` shows the traceback)"),
    (EXIT_INTERRUPTED, "interrupted (SIGINT or SIGTERM); no partial output is left"),
)
"""The exit-code table, in the order the README documents it."""


def exit_code_table() -> str:
    """The exit-code table as Markdown, exactly as the README carries it."""
    rows = ["| code | meaning |", "| --- | --- |"]
    rows += [f"| {code} | {meaning} |" for code, meaning in EXIT_CODES]
    return "\n".join(rows)
