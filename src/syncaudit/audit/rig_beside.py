"""The rig kept beside a remote log (`LOG.rig.yaml` next to `LOG`), as beside a local one.

A local audit without `--rig` uses `LOG.rig.yaml` when it lies beside the log; a fleet
that uploads logs with their rigs expects the same of `syncaudit audit s3://.../LOG`. The
rig is asked for in one request (`remote.sidecar`): none there, the rig is guessed as for
a local log without one; refused (a URL signed for the log alone), it is guessed and the
refusal said, so the user knows to pass `--rig`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from syncaudit.config import decode_text
from syncaudit.errors import InputOpenError
from syncaudit.remote.sidecar import Sidecar, beside, read_small
from syncaudit.remote.urls import is_url
from syncaudit.rig import Rig, load_rig, rig_from_text

RIG_SUFFIX = ".rig.yaml"


@dataclass(frozen=True, slots=True)
class RigBeside:
    """The rig found beside a remote log (None: guess it) and one line saying what was done."""

    rig: Rig | None
    said: str | None


def remote_rig_beside(log_url: str) -> RigBeside:
    """The rig `LOG.rig.yaml` beside the log at `log_url`, validated like a rig file.

    Raises:
        ConfigError: the rig there is not a valid rig file (exit 6, naming its URL).
        LogReadError: the server failed to answer for it.
    """
    found = rig_sidecar(log_url)
    if found.data is None:
        if found.refused is None:
            return RigBeside(None, None)
        return RigBeside(
            None,
            f"cannot read the rig beside the log ({found.name}: {found.refused}): guessing it "
            "(--rig to give one)",
        )
    rig = _rig(found.data, found.name)
    name = found.name.rsplit("/", 1)[-1]
    return RigBeside(
        rig, f"using rig {name} beside the log (--rig to choose another, --no-rig to guess)"
    )


def local_rig_beside(log: Path) -> Path | None:
    """The file `LOG.rig.yaml` beside a local log, where there is one."""
    beside_log = log.with_name(log.name + RIG_SUFFIX)
    return beside_log if beside_log.is_file() else None


def rig_sidecar(log_url: str) -> Sidecar:
    """What lies at `LOG.rig.yaml` beside the remote log (its bytes, or None and why)."""
    return read_small(beside(log_url, RIG_SUFFIX))


def load_rig_at(location: str | Path) -> Rig:
    """A rig file by path or URL (the gate's jobs name a remote log's rig by its URL).

    Raises:
        InputOpenError: nothing readable there (exit 2).
        ConfigError: not a valid rig file.
    """
    if isinstance(location, Path) or not is_url(location):
        return load_rig(location)
    found = read_small(location)
    if found.data is None:
        why = found.refused or "no such object"
        raise InputOpenError(f"{found.name}: cannot read rig file ({why})")
    return _rig(found.data, found.name)


def _rig(data: bytes, name: str) -> Rig:
    return rig_from_text(decode_text(data, name, what="rig file"), name)
