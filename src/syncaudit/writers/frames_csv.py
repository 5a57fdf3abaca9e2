"""The per-frame table of an audit as CSV (what `audit --csv` writes)."""

from __future__ import annotations

import io
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from syncaudit.audit.run import AuditResult

FRAME_TABLE_COLUMNS: tuple[str, ...] = (
    "camera",
    "frame_sequence",
    "exposure_start_ns",
    "exposure_duration_ns",
    "t_l_ns",
    "t_estimated_ns",
    "error_signed_ns",
    "t_error_ns",
    "paired",
    "revolution",
    "revolution_start_ns",
    "header_stamp_ns",
    "t1_ns",
    "t2_ns",
    "t3_ns",
    "t4_ns",
    "t5_avg_ns",
    "t_rotate_ns",
    "packet_phase_ns",
    "packet_phase_source",
    "t_sleep_ns",
    "applied_delay_ns",
    "rolling_error_mean_ns",
    "rolling_error_var_ns2",
)
"""Columns of `AuditResult.frames()`; written as the header even when no camera was audited
(a test keeps this equal to what the analysis produces)."""


def frames_csv(result: AuditResult) -> str:
    """The per-frame table of every camera as CSV text, header always present."""
    frames = result.frames()
    if frames.empty and len(frames.columns) == 0:
        return ",".join(FRAME_TABLE_COLUMNS) + "\n"
    buffer = io.StringIO()
    frames.to_csv(buffer, index=False)
    return buffer.getvalue()
