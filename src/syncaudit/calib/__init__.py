"""Method B: calibrate and validate LiDARs with non-overlapping views from a turning vehicle.

The registration stack (small_gicp, gtsam) is the optional extra `syncaudit[calib]`; it is
imported only when `calibrate_log` runs, so the simulator and the report work without it.
"""

from syncaudit.calib.pipeline import calibrate_log
from syncaudit.calib.result import CalibrationResult
from syncaudit.calib.settings import (
    AlignmentLimits,
    CalibConfig,
    MapToMapConfig,
    PoseGraphConfig,
    RegistrationConfig,
    SelectionConfig,
    ValidationConfig,
    load_config,
)
from syncaudit.report.calib_section import html_section, render_calibration, render_calibration_html

__all__ = [
    "AlignmentLimits",
    "CalibConfig",
    "CalibrationResult",
    "MapToMapConfig",
    "PoseGraphConfig",
    "RegistrationConfig",
    "SelectionConfig",
    "ValidationConfig",
    "calibrate_log",
    "html_section",
    "load_config",
    "render_calibration",
    "render_calibration_html",
]
