"""Camera columns as pandas frames: one row per image frame, one row per trigger."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

FRAME_COLUMNS: dict[str, str] = {
    "camera": "string",
    "frame_sequence": "Int64",
    "header_stamp_ns": "Int64",
    "log_time_ns": "int64",
    "exposure_start_ns": "Int64",
    "exposure_duration_ns": "Int64",
    "source": "string",
}
"""Frame table: exposure fields are <NA> where the log has no exposure metadata."""

TRIGGER_COLUMNS: dict[str, str] = {
    "camera": "string",
    "frame_sequence": "Int64",
    "log_time_ns": "int64",
    "lidar_packet_ns": "Int64",
    "lidar_driver_ns": "Int64",
    "camera_driver_ns": "Int64",
    "camera_sensor_ns": "Int64",
    "exposure_start_ns": "Int64",
    "applied_delay_ns": "Int64",
    "source": "string",
}
"""Trigger table: the five checkpoints 240..248 of the method, <NA> where not recorded."""


def _empty(columns: dict[str, str]) -> pd.DataFrame:
    import pandas as pd  # deferred: worker processes never need pandas

    return pd.DataFrame({k: pd.Series(np.array([]), dtype=v) for k, v in columns.items()})


def empty_frames() -> pd.DataFrame:
    """A frame table with no rows and the right dtypes."""
    return _empty(FRAME_COLUMNS)


def empty_triggers() -> pd.DataFrame:
    """A trigger table with no rows and the right dtypes."""
    return _empty(TRIGGER_COLUMNS)
