"""The per-frame table of an audit as CSV (what `audit --csv` writes)."""

from __future__ import annotations

import io

from syncaudit.columns.audit_result import AuditedLog
from syncaudit.columns.frame_table import FRAME_TABLE_COLUMNS

__all__ = ["FRAME_TABLE_COLUMNS", "frames_csv"]


def frames_csv(result: AuditedLog) -> str:
    """The per-frame table of every camera as CSV text, the header (the analysis' frame
    table columns) present even when no camera was audited."""
    frames = result.frames()
    if frames.empty and len(frames.columns) == 0:
        return ",".join(FRAME_TABLE_COLUMNS) + "\n"
    buffer = io.StringIO()
    frames.to_csv(buffer, index=False)
    return buffer.getvalue()
