"""Configuration of the LiDAR calibration (method B), as pydantic models.

The simulated sessions' settings live with the simulator (`syncaudit.simulate.calib_config`).

Every model raises `ConfigError` with a one-line message instead of pydantic's multi-line
`ValidationError`, so nonsense settings surface as the CLI's config exit code.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, model_validator

from syncaudit.config import ConfigModel as ConfigModel
from syncaudit.config import load_model

# --------------------------------------------------------------------------- calibration


def _check_stages(stages_m: tuple[float, ...]) -> None:
    """Correspondence distances must be positive and non-increasing (coarse to fine)."""
    if not stages_m or any(v <= 0 for v in stages_m):
        raise ValueError("correspondence_stages_m must be positive distances")
    if any(b > a for a, b in itertools.pairwise(stages_m)):
        raise ValueError("correspondence_stages_m must not increase (coarse to fine)")


class AlignmentLimits(ConfigModel):
    """How a registration runs (coarse-to-fine distances) and when its result is trusted.

    Acceptance rests on the point-to-plane error and the conditioning; overlap is judged
    relative to what the two views can share from where they were taken (the fraction of
    the source the target's field of view covers at the seed pose), with an absolute floor
    below which too little is shared to check anything.
    """

    correspondence_stages_m: tuple[float, ...] = (1.0, 0.3, 0.15)
    overlap_distance_m: float = Field(default=0.2, gt=0.0)
    min_overlap: float = Field(default=0.1, gt=0.0, le=1.0)
    """Absolute floor of the overlapping fraction of the source."""
    min_overlap_ratio: float = Field(default=0.3, gt=0.0, le=1.0)
    """Overlap must reach this share of the overlap the views allow (when it is known)."""
    max_rmse_m: float = Field(default=0.05, gt=0.0)
    min_translation_information: float = Field(default=0.03, gt=0.0, lt=1.0)
    min_rotation_information: float = Field(default=0.01, gt=0.0, lt=1.0)

    @model_validator(mode="after")
    def _check(self) -> AlignmentLimits:
        _check_stages(self.correspondence_stages_m)
        return self


class SelectionConfig(ConfigModel):
    """How scans are grouped into stops and which stops and pairs are used."""

    min_stops: int = Field(default=3, ge=2)
    min_static_scans: int = Field(default=2, ge=2)
    static_residual_m: float = Field(default=0.02, gt=0.0)
    """Median nearest-neighbour distance between consecutive still scans (raised
    automatically for noisier LiDARs: 1.5x the quietest tenth of a LiDAR's pairs)."""
    static_near_fraction: float = Field(default=0.9, gt=0.0, le=1.0)
    """Share of a still scan's points within 5 cm of the previous scan."""
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
    coarse_voxel_m: float = Field(default=0.5, gt=0.0)
    coarse_max_correspondence_m: float = Field(default=2.5, gt=0.0)
    yaw_search_step_deg: float = Field(default=10.0, gt=0.0, le=90.0)
    turn_min_translation_information: float = Field(default=0.01, gt=0.0, lt=1.0)
    turn_min_rotation_information: float = Field(default=0.005, gt=0.0, lt=1.0)
    """The coarse turn between stops (all LiDARs merged) is trusted as a seed above these."""
    max_step_deg: float = Field(default=90.0, gt=0.0, le=180.0)
    """Largest turn searched between consecutive stops; views overlap only below ~90 deg."""
    max_iterations: int = Field(default=30, ge=5)
    limits: AlignmentLimits = AlignmentLimits()
    num_threads: int = Field(default=2, ge=1, le=64)

    @model_validator(mode="after")
    def _check(self) -> RegistrationConfig:
        if self.coarse_voxel_m < self.voxel_m:
            raise ValueError("coarse_voxel_m must be >= voxel_m")
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
    joint_link_sigma_m: float = Field(default=0.0006, gt=0.0)
    """edge_sigma_m of the joint graph's scan and cross-LiDAR links in its final solve
    (information: the alignment's mean Hessian over its square; the first solve, which
    only seeds the cross pairs, keeps edge_sigma_m), set by their whitened residuals at the
    simulator's true poses and extrinsic: at 1 cm the median link's chi2/dof was
    0.0002-0.013 over seed 0's 13 matrix sessions (the 0.05 deg planar prior outweighed
    them); at 0.6 mm it is 0.06-0.9 with 32-128 beams and 0.9-3.6 with 16 (their
    alignments are worse than their Hessian says; at 0.3 mm the kernel discounts them:
    parking-16-roof 0.0038 -> 0.0083 deg)."""


class MapToMapConfig(ConfigModel):
    """GICP between the LiDARs' local maps (the extrinsic calibration step)."""

    voxel_m: float = Field(default=0.1, gt=0.0)
    neighbours: int = Field(default=30, ge=5, le=100)
    limits: AlignmentLimits = AlignmentLimits(
        min_overlap=0.05, min_translation_information=0.01, min_rotation_information=0.005
    )


class ValidationConfig(ConfigModel):
    """Limits for the difference between calibrated and recorded extrinsics."""

    max_rotation_deg: float = Field(default=0.25, gt=0.0)
    max_translation_cm: float = Field(default=2.0, gt=0.0)


class MovingScansConfig(ConfigModel):
    """Scans taken while moving (`alignment.moving_scans`): when they join the joint graph."""

    use: Literal["auto", "always", "never"] = "never"
    """never (the default): none join, each LiDAR's report still says how many there were;
    always: every moving scan that passes the tests; auto: the still scans a LiDAR's run
    detection missed at another LiDAR's stop, and the deskewed ones only where the stops
    alone leave some extrinsic's 1-sigma above `weak_share` of the validation limits. Not
    the default because, measured, they did not make a calibration better: on seed 0 of
    the matrix, added at half the limits (8 of 13 sessions), they moved the error by
    -0.008 to +0.177 cm and -0.0004 to +0.0053 deg and cost 4-12 CPU s; at the limits
    (run on parking-64-facing-bumper seeds 0-2, the loosest case) seed 0 went from
    1.006 to 1.183 cm, seeds 1 and 2 kept their free direction (benchmarks/README.md).
    A deskewed scan's pose is only as good as the estimated motion."""
    weak_share: float = Field(default=1.0, gt=0.0, le=10.0)
    max_per_gap: int = Field(default=3, ge=1, le=50)
    """Moving scans tried per LiDAR between two consecutive stops (evenly spread in time)."""
    sharp_ratio: float = Field(default=1.5, ge=1.0)
    """A moving scan's fit error may be at most this many times the stop pairs' median."""
    velocity_uncertainty: float = Field(default=0.2, ge=0.0)
    """Share of the deskew's correction taken as its uncertainty in the links' weight."""


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
    moving_scans: MovingScansConfig = MovingScansConfig()

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
