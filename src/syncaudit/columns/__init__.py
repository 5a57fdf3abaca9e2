"""Extracted columns: what readers produce and the analysis consumes (numpy `Table`s).

Conventions: every time is int64 nanoseconds in the host clock unless the name says
`sensor_`; durations in ns as int64 (`_ns`) or float seconds (`_s`); angles in degrees.
"""

from syncaudit.columns.camera import FRAME_COLUMNS, TRIGGER_COLUMNS
from syncaudit.columns.lidar import RevolutionColumns

__all__ = ["FRAME_COLUMNS", "TRIGGER_COLUMNS", "RevolutionColumns"]
