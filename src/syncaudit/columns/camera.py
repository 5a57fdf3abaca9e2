"""Camera columns: one row per image frame, one row per trigger (`columns.table.Table`s; these
are their pandas dtypes, see the table there for how each is held in numpy), and one
camera's tables together (`CameraTables`, as `camera.extract` builds them)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from syncaudit.columns.sequence_counter import SequenceCounter

if TYPE_CHECKING:
    from syncaudit.columns.table import Table

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


@dataclass(frozen=True, slots=True)
class CameraTables:
    """Everything one camera's topics say, as tables."""

    name: str
    images: Table
    """header_stamp_ns, log_time_ns, frame_sequence (ROS 1 seq), frame_id of every image."""
    frames: Table
    """FRAME_COLUMNS: one row per exposure record (or per image where there are none), in
    log-time order."""
    triggers: Table
    """TRIGGER_COLUMNS, in the order the log gave them."""
    exposure_source: str | None
    trigger_source: str | None
    warnings: tuple[str, ...] = ()
    """Damaged messages skipped, one line per topic."""
    shared_topic_notes: tuple[str, ...] = ()
    """Why messages of a topic this camera shares with others could not be given to it
    (nothing in them tells the cameras apart): the reason it is not judged, if it is not."""
    frame_counter: SequenceCounter | None = None
    """What the frames' `frame_sequence` numbers count (None: unknown, as one camera's)."""
    trigger_counter: SequenceCounter | None = None
    """What the triggers' `frame_sequence` numbers count."""


CAMERA_EXPOSURE = "syncaudit_msgs/msg/CameraExposure"
"""The one exposure type stating its exposure start; the others' follow the rig's `stamp`."""
