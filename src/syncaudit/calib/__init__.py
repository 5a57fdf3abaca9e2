"""Method B: calibrate and validate LiDARs with non-overlapping views from a turning vehicle.

The registration stack (small_gicp, gtsam) is the optional extra `syncaudit[calib]`; it is
imported only when `calibrate_log` runs, so the simulator and the report work without it.
"""

from syncaudit.calib.pipeline import calibrate_log
from syncaudit.calib.result import CalibrationResult
from syncaudit.calib.settings import (
    AlignmentLimits,
    CalibConfig,
    CalibSceneConfig,
    LidarSimConfig,
    MapToMapConfig,
    PoseGraphConfig,
    RegistrationConfig,
    SceneConfig,
    SelectionConfig,
    ValidationConfig,
    calib_scene_config,
    load_config,
    mount_preset,
    rig_preset,
)
from syncaudit.report.calib_section import html_section, render_calibration, render_calibration_html

__all__ = [
    "AlignmentLimits",
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
    "calib_scene_config",
    "calibrate_log",
    "html_section",
    "load_config",
    "mount_preset",
    "render_calibration",
    "render_calibration_html",
    "rig_preset",
]
