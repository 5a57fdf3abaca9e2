"""Method B: calibrate and validate LiDARs with non-overlapping views from a turning vehicle.

The registration stack (small_gicp, gtsam) is the optional extra `syncaudit[calib]`; it is
imported only when `calibrate_log` runs, so the simulator and the report work without it.
The result is rendered by `syncaudit.report` (`calib_section`, `report_page`), which sits
above this package.
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
    "load_config",
]
