"""Method B: calibrate and validate LiDARs with non-overlapping views from a turning vehicle.

The registration stack (small_gicp, gtsam) is the optional extra `syncaudit[calib]`; it is
imported only when `calibrate_log` runs, so the simulator and the report work without it.
"""

from syncaudit.calib.config import (
    CalibConfig,
    CalibSceneConfig,
    LidarSimConfig,
    MapToMapConfig,
    PoseGraphConfig,
    RegistrationConfig,
    SceneConfig,
    SelectionConfig,
    ValidationConfig,
    load_config,
    rig_preset,
)
from syncaudit.calib.pipeline import calibrate_log
from syncaudit.calib.report import html_section, render_calibration
from syncaudit.calib.result import CalibrationResult

__all__ = [
    "CalibConfig",
    "CalibSceneConfig",
    "CalibrationResult",
    "LidarSimConfig",
    "MapToMapConfig",
    "PoseGraphConfig",
    "RegistrationConfig",
    "SceneConfig",
    "SelectionConfig",
    "ValidationConfig",
    "calibrate_log",
    "html_section",
    "load_config",
    "render_calibration",
    "rig_preset",
]
