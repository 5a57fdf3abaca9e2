"""Camera columns: one row per image frame, one row per trigger (`columns.table.Table`s; these
are their pandas dtypes, see the table there for how each is held in numpy)."""

from __future__ import annotations

FRAME_COLUMNS: dict[str, str] = {
    "camera": "string",
    "frame_sequence": "Int64",
    "header_stamp_ns": "Int64",
    "log_time_ns": "int64",
    "exposure_start_ns": "Int64",
    "exposure_duration_ns": "Int64",
    "source": "string",
    "frame_id": "string",
}
"""Frame table: exposure fields are <NA> where the log has no exposure metadata; frame_id is
the header.frame_id of the message the row came from ("" where it has none)."""

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
    "frame_id": "string",
}
"""Trigger table: the five checkpoints 240..248 of the method, <NA> where not recorded;
frame_id as in the frame table (TimeReference: its `source` where the header has none)."""
