"""The per-frame table of an audited camera: its columns and their DataFrame dtypes.

`analysis.sync` fills it (one row per frame: stamps, pairing, latencies, errors); the
CSV, Parquet and pairing writers read it by these names.
"""

from __future__ import annotations

FRAME_TABLE_DTYPES: dict[str, str] = {
    "camera": "string",
    "frame_sequence": "Int64",
    "exposure_start_ns": "Int64",
    "exposure_duration_ns": "Int64",
    "t_l_ns": "Int64",
    "t_estimated_ns": "Int64",
    "error_signed_ns": "float64",
    "t_error_ns": "float64",
    "paired": "bool",
    "revolution": "int64",
    "revolution_start_ns": "Int64",
    "header_stamp_ns": "Int64",
    "t1_ns": "float64",
    "t2_ns": "float64",
    "t3_ns": "float64",
    "t4_ns": "float64",
    "t5_avg_ns": "float64",
    "t_rotate_ns": "float64",
    "packet_phase_ns": "float64",
    "packet_phase_source": "string",
    "t_sleep_ns": "float64",
    "applied_delay_ns": "float64",
    "rolling_error_mean_ns": "float64",
    "rolling_error_var_ns2": "float64",
    "advised_delay_ns": "float64",
}
"""The per-frame table's columns and their DataFrame dtypes (stamps Int64 ns)."""

FRAME_TABLE_COLUMNS: tuple[str, ...] = tuple(FRAME_TABLE_DTYPES)
"""The column names, in order."""
