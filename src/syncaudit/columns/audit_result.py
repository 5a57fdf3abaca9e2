"""What the writers read of an audit's result: its schema version and its shape.

`audit.run.AuditResult` is the result; the writers (CSV, Parquet, pairings) sit beside the
audit, not above it, so they name the result by these structural types (`Protocol`s, no
logic) and `audit.run` stays free to grow.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    import pandas as pd

    from syncaudit.rig import Rig

SCHEMA_VERSION = 1
"""Version of the audit's JSON (schemas/audit.schema.json) and of the Parquet metadata."""


class SyncedCamera(Protocol):
    """One camera's synchronisation figures (`analysis.sync.CameraSync`)."""

    @property
    def camera(self) -> str:
        """The camera's name."""
        ...

    @property
    def unpaired(self) -> dict[str, int]:
        """Frames not paired, by reason."""
        ...

    @property
    def frames(self) -> pd.DataFrame:
        """The per-frame table (`columns.frame_table.FRAME_TABLE_DTYPES`)."""
        ...


class AuditedCamera(Protocol):
    """One camera of an audit (`audit.run.CameraAudit`)."""

    @property
    def sync(self) -> SyncedCamera:
        """Its synchronisation figures."""
        ...

    def to_dict(self) -> dict[str, Any]:
        """Its JSON form."""
        ...


class AuditedLog(Protocol):
    """The audit of one log (`audit.run.AuditResult`)."""

    @property
    def path(self) -> str:
        """The log."""
        ...

    @property
    def rig(self) -> Rig:
        """The rig it was audited with (given or guessed)."""
        ...

    @property
    def clock_offset_ns(self) -> int:
        """Host minus LiDAR clock."""
        ...

    @property
    def start_ns(self) -> int | None:
        """Log start (host clock)."""
        ...

    @property
    def verdict(self) -> str:
        """'pass', 'fail', 'not judged' or 'no cameras'."""
        ...

    @property
    def cameras(self) -> Sequence[AuditedCamera]:
        """Every audited camera."""
        ...

    def frames(self) -> pd.DataFrame:
        """Every camera's per-frame table, concatenated."""
        ...
