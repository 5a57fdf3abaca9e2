"""Configuration of the LiDAR calibration (method B) and of its simulated sessions, as pydantic models.

Every model raises `ConfigError` with a one-line message instead of pydantic's multi-line
`ValidationError`, so nonsense settings surface as the CLI's config exit code.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, model_validator

from syncaudit.config import ConfigModel as ConfigModel
from syncaudit.config import load_model

# --------------------------------------------------------------------------- simulation


class LidarSimConfig(ConfigModel):
    """One simulated LiDAR: beam pattern, range model and mounting on the vehicle."""

    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_]+$")
    topic: str | None = None
    frame_id: str | None = None
    beams: int = Field(default=32, ge=2, le=512)
    vertical_fov_deg: tuple[float, float] = (-25.0, 15.0)
    horizontal_fov_deg: float = Field(default=120.0, gt=0.0, le=360.0)
    horizontal_resolution_deg: float = Field(default=0.2, gt=0.01, le=5.0)
    min_range_m: float = Field(default=0.5, ge=0.0)
    max_range_m: float = Field(default=80.0, gt=0.0)
    range_noise_m: float = Field(default=0.01, ge=0.0, le=0.5)
    mount_xyz_m: tuple[float, float, float] = (0.0, 0.0, 1.9)
    mount_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    recorded_rotation_error_deg: float = Field(default=0.0, ge=0.0, le=45.0)
    recorded_translation_error_cm: float = Field(default=0.0, ge=0.0, le=100.0)

    @model_validator(mode="after")
    def _check(self) -> LidarSimConfig:
        lo, hi = self.vertical_fov_deg
        if not -90.0 <= lo < hi <= 90.0:
            raise ValueError("vertical_fov_deg must be (low, high) with -90 <= low < high <= 90")
        if self.max_range_m <= self.min_range_m:
            raise ValueError("max_range_m must exceed min_range_m")
        return self

    @property
    def topic_name(self) -> str:
        """Topic the LiDAR publishes on."""
        return self.topic or f"/lidar/{self.name}/points"

    @property
    def frame(self) -> str:
        """Frame id of the LiDAR's points."""
        return self.frame_id or f"lidar_{self.name}"


class SceneConfig(ConfigModel):
    """What the ray-cast calibration environment contains."""

    kind: Literal["yard", "ground_and_wall"] = "yard"
    yard_size_m: tuple[float, float] = (26.0, 20.0)
    n_boxes: int = Field(default=8, ge=0, le=200)
    n_poles: int = Field(default=10, ge=0, le=200)
    clear_radius_m: float = Field(default=4.0, ge=0.0)

    @model_validator(mode="after")
    def _check(self) -> SceneConfig:
        half = min(self.yard_size_m) / 2.0
        if min(self.yard_size_m) <= 0:
            raise ValueError("yard_size_m must be positive")
        if self.kind == "yard" and half <= self.clear_radius_m + 1.0:
            raise ValueError("yard_size_m too small for clear_radius_m (no room for objects)")
        return self


def rig_preset(
    beams: int = 32,
    *,
    range_noise_m: float = 0.01,
    rear_rotation_error_deg: float = 0.05,
    rear_translation_error_cm: float = 0.3,
) -> list[LidarSimConfig]:
    """A front and a rear roof LiDAR with 120 deg views (non-overlapping), for `beams` channels.

    Up to 32 beams: -25..15 deg vertical, 0.2 deg columns (a VLP-32C-like pattern); more:
    -22.5..22.5 deg, 0.35 deg columns (an OS1-128-like pattern). The rear LiDAR's recorded
    extrinsic is off by `rear_rotation_error_deg` / `rear_translation_error_cm`.
    """
    if beams <= 32:
        vfov_deg, res_deg = (-25.0, 15.0), 0.2
    else:
        vfov_deg, res_deg = (-22.5, 22.5), 0.35
    common: dict[str, Any] = {
        "beams": beams,
        "horizontal_fov_deg": 120.0,
        "vertical_fov_deg": vfov_deg,
        "horizontal_resolution_deg": res_deg,
        "range_noise_m": range_noise_m,
    }
    front = LidarSimConfig(
        name="front", mount_xyz_m=(2.2, 0.05, 1.95), mount_rpy_deg=(0.4, 4.0, 1.5), **common
    )
    rear = LidarSimConfig(
        name="rear",
        mount_xyz_m=(-0.6, -0.08, 1.85),
        mount_rpy_deg=(-0.8, 6.0, 178.0),
        recorded_rotation_error_deg=rear_rotation_error_deg,
        recorded_translation_error_cm=rear_translation_error_cm,
        **common,
    )
    return [front, rear]


def _sector_overlap_deg(a_center: float, a_width: float, b_center: float, b_width: float) -> float:
    """Angular overlap (deg) of two horizontal sectors given by centre and width."""
    gap = abs((a_center - b_center + 180.0) % 360.0 - 180.0)
    return max(0.0, (a_width + b_width) / 2.0 - gap)


class CalibSceneConfig(ConfigModel):
    """A simulated turntable (or slow-turn) calibration session."""

    seed: int = 0
    n_stops: int = Field(default=12, ge=2, le=720)
    sweep_deg: float = Field(default=360.0, gt=0.0, le=360.0)
    pivot_in_base_m: tuple[float, float] = (1.4, 0.0)
    stop_jitter_deg: float = Field(default=0.2, ge=0.0, le=10.0)
    stop_jitter_m: float = Field(default=0.01, ge=0.0, le=1.0)
    scans_per_stop: int = Field(default=1, ge=1, le=50)
    turning_scans: int = Field(default=0, ge=0, le=50)
    scan_period_s: float = Field(default=0.1, gt=0.0, le=2.0)
    turn_duration_s: float = Field(default=2.0, gt=0.0, le=600.0)
    start_time_s: float = Field(default=1_700_000_000.0, ge=0.0)
    base_frame: str = Field(default="base_link", min_length=1)
    tf_topic: str = "/tf_static"
    scene: SceneConfig = SceneConfig()
    lidars: list[LidarSimConfig] = Field(default_factory=rig_preset)

    @model_validator(mode="after")
    def _check(self) -> CalibSceneConfig:
        if len(self.lidars) < 2:
            raise ValueError("a calibration session needs two or more LiDARs")
        for attr in ("name", "topic_name", "frame"):
            values = [getattr(lidar, attr) for lidar in self.lidars]
            if len(set(values)) != len(values):
                raise ValueError(f"LiDAR {attr} values must be unique")
        if self.base_frame in {lidar.frame for lidar in self.lidars}:
            raise ValueError("base_frame must differ from the LiDAR frames")
        for i, a in enumerate(self.lidars):
            for b in self.lidars[i + 1 :]:
                overlap = _sector_overlap_deg(
                    a.mount_rpy_deg[2],
                    a.horizontal_fov_deg,
                    b.mount_rpy_deg[2],
                    b.horizontal_fov_deg,
                )
                if overlap > 0:
                    raise ValueError(
                        f"LiDARs {a.name} and {b.name} overlap by {overlap:.1f} deg; "
                        "method B is for non-overlapping views"
                    )
        if self.turning_scans > 0 and self.scans_per_stop < 2:
            raise ValueError("turning_scans need scans_per_stop >= 2 so stops can be told apart")
        return self

    @property
    def step_deg(self) -> float:
        """Turntable angle between consecutive stops."""
        if math.isclose(self.sweep_deg, 360.0):
            return self.sweep_deg / self.n_stops
        return self.sweep_deg / (self.n_stops - 1)


# --------------------------------------------------------------------------- calibration


def _check_stages(stages_m: tuple[float, ...]) -> None:
    """Correspondence distances must be positive and non-increasing (coarse to fine)."""
    if not stages_m or any(v <= 0 for v in stages_m):
        raise ValueError("correspondence_stages_m must be positive distances")
    if any(b > a for a, b in itertools.pairwise(stages_m)):
        raise ValueError("correspondence_stages_m must not increase (coarse to fine)")


class SelectionConfig(ConfigModel):
    """How scans are grouped into stops and which stops and pairs are used."""

    min_stops: int = Field(default=3, ge=2)
    min_static_scans: int = Field(default=2, ge=2)
    static_rotation_deg: float = Field(default=0.1, gt=0.0)
    static_translation_m: float = Field(default=0.02, gt=0.0)
    max_static_gap_s: float = Field(default=0.5, gt=0.0)
    stop_match_tolerance_s: float = Field(default=0.3, ge=0.0)
    min_step_deg: float = Field(default=2.0, ge=0.0)
    min_predicted_overlap: float = Field(default=0.4, gt=0.0, lt=1.0)
    max_pairs_per_scan: int = Field(default=4, ge=1)
    reference_stop: int | None = Field(default=None, ge=0)


class RegistrationConfig(ConfigModel):
    """Cross-scan GICP (small_gicp) and its acceptance tests."""

    voxel_m: float = Field(default=0.15, gt=0.0)
    neighbours: int = Field(default=30, ge=5, le=100)
    correspondence_stages_m: tuple[float, ...] = (1.0, 0.3, 0.15)
    coarse_voxel_m: float = Field(default=0.5, gt=0.0)
    coarse_max_correspondence_m: float = Field(default=2.5, gt=0.0)
    yaw_search_step_deg: float = Field(default=10.0, gt=0.0, le=90.0)
    turn_min_translation_information: float = Field(default=0.01, gt=0.0, lt=1.0)
    turn_min_rotation_information: float = Field(default=0.005, gt=0.0, lt=1.0)
    """The coarse turn between stops (all LiDARs merged) is trusted as a seed above these."""
    max_step_deg: float = Field(default=90.0, gt=0.0, le=180.0)
    """Largest turn searched between consecutive stops; views overlap only below ~90 deg."""
    max_iterations: int = Field(default=30, ge=5)
    overlap_distance_m: float = Field(default=0.2, gt=0.0)
    min_overlap: float = Field(default=0.4, gt=0.0, le=1.0)
    max_rmse_m: float = Field(default=0.05, gt=0.0)
    min_translation_information: float = Field(default=0.03, gt=0.0, lt=1.0)
    min_rotation_information: float = Field(default=0.01, gt=0.0, lt=1.0)
    num_threads: int = Field(default=2, ge=1, le=64)

    @model_validator(mode="after")
    def _check(self) -> RegistrationConfig:
        if self.coarse_voxel_m < self.voxel_m:
            raise ValueError("coarse_voxel_m must be >= voxel_m")
        _check_stages(self.correspondence_stages_m)
        return self


class PoseGraphConfig(ConfigModel):
    """Per-LiDAR pose graph (gtsam) with a robust kernel."""

    motion: Literal["planar", "free"] = "planar"
    """planar: the vehicle turns on a flat floor (turntable or slow turn), so the stops of a
    LiDAR differ by a rotation about one axis (estimated from the alignments, not taken
    from the recorded extrinsic) and a shift across it: an SE(2) graph, which cannot drift
    in tilt. free: full SE(3) poses."""
    kernel: Literal["cauchy", "huber"] = "cauchy"
    kernel_width: float = Field(default=2.0, gt=0.0)
    edge_sigma_m: float = Field(default=0.01, gt=0.0)
    """An edge's information is its mean point-to-plane Hessian over edge_sigma_m^2: a
    direction every correspondence constrains gets about this standard deviation, one
    that a fraction f of them constrains gets edge_sigma_m / sqrt(f)."""
    max_edge_residual_sigmas: float = Field(default=4.0, gt=0.0)
    max_iterations: int = Field(default=100, ge=1)


class MapToMapConfig(ConfigModel):
    """GICP between the LiDARs' local maps (the extrinsic calibration step)."""

    voxel_m: float = Field(default=0.1, gt=0.0)
    neighbours: int = Field(default=30, ge=5, le=100)
    correspondence_stages_m: tuple[float, ...] = (1.0, 0.3, 0.15)
    overlap_distance_m: float = Field(default=0.2, gt=0.0)
    min_overlap: float = Field(default=0.2, gt=0.0, le=1.0)
    max_rmse_m: float = Field(default=0.05, gt=0.0)
    min_translation_information: float = Field(default=0.01, gt=0.0, lt=1.0)
    min_rotation_information: float = Field(default=0.005, gt=0.0, lt=1.0)

    @model_validator(mode="after")
    def _check(self) -> MapToMapConfig:
        _check_stages(self.correspondence_stages_m)
        return self


class ValidationConfig(ConfigModel):
    """Limits for the difference between calibrated and recorded extrinsics."""

    max_rotation_deg: float = Field(default=0.25, gt=0.0)
    max_translation_cm: float = Field(default=2.0, gt=0.0)


class CalibConfig(ConfigModel):
    """Everything `calibrate_log` needs besides the log."""

    lidar_topics: list[str] | None = None
    reference_topic: str | None = None
    extrinsics_file: Path | None = None
    tf_topic: str = "/tf_static"
    selection: SelectionConfig = SelectionConfig()
    registration: RegistrationConfig = RegistrationConfig()
    pose_graph: PoseGraphConfig = PoseGraphConfig()
    map_to_map: MapToMapConfig = MapToMapConfig()
    validation: ValidationConfig = ValidationConfig()

    @model_validator(mode="after")
    def _check(self) -> CalibConfig:
        if self.lidar_topics is not None:
            if len(self.lidar_topics) < 2:
                raise ValueError("lidar_topics needs two or more topics")
            if len(set(self.lidar_topics)) != len(self.lidar_topics):
                raise ValueError("lidar_topics must be unique")
            if self.reference_topic and self.reference_topic not in self.lidar_topics:
                raise ValueError("reference_topic must be one of lidar_topics")
        return self


def load_config(path: Path, model: type[ConfigModel]) -> Any:
    """Read a YAML, JSON (.json) or TOML (.toml) file into `model` (`syncaudit.config`).

    Raises:
        ConfigError: `path: key.path: message` for unreadable or invalid content.
    """
    return load_model(path, model, what="calibration config")
