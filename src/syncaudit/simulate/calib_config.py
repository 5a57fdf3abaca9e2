"""Settings of a simulated calibration session (method B): LiDARs, scene, motion, presets.

The simulator's own models, apart from the calibration's (`syncaudit.calib.settings`), so
that the simulator imports nothing it is checked by. Every model raises `ConfigError` with
a one-line message (`syncaudit.config.ConfigModel`).
"""

from __future__ import annotations

import math
from typing import Any, Literal

from pydantic import Field, model_validator

from syncaudit.config import ConfigModel
from syncaudit.simulate import SceneKind


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
    organized: bool = False
    """Publish an organised beam x column cloud (height = beams, zeros for no return, the
    ouster-ros layout) instead of an unorganised dense one (the Velodyne driver's)."""

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

    kind: SceneKind = "yard"
    """yard: walls, boxes and poles; ground_and_wall: flat ground and one long wall;
    corridor: flat ground between two long parallel walls (both degenerate); parking_lot:
    rows of parked cars with gaps, lamp posts and a building on one side, no enclosing walls;
    parking_lot_open: the same with cars on one side of the aisle only (the other LiDAR sees
    open tarmac at several stops); parking_lot_facing: the one-sided lot with its aisle 30 deg
    left of the vehicle's start heading (not rotated at random) and, in
    `calib_scene_config`, driven with 8-16 deg left turns, so a front LiDAR sees the cars at
    every stop and a rear-facing one only at the first few (open tarmac at most stops)."""
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


MountPreset = Literal["roof_front_rear", "roof_left_right", "bumper_front_rear", "diagonal"]
"""Where the two LiDARs sit: roof front/rear, roof left/right (sideways), bumper-height
front/rear (low, ground-dominated views), diagonal corners (front-left, rear-right)."""

DEFAULT_MOUNT: MountPreset = "roof_front_rear"
"""The mount of a session that names none (`calib_scene_config`, `simulate calib`)."""

_MOUNTS: dict[str, tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...]] = {
    "roof_front_rear": (
        ((2.2, 0.05, 1.95), (0.4, 4.0, 1.5)),
        ((-0.6, -0.08, 1.85), (-0.8, 6.0, 178.0)),
    ),
    "roof_left_right": (
        ((1.2, 0.85, 1.9), (1.0, 3.0, 88.0)),
        ((1.1, -0.82, 1.92), (-1.2, 2.5, -91.0)),
    ),
    "bumper_front_rear": (
        ((3.75, 0.02, 0.52), (0.3, 1.5, 0.8)),
        ((-0.95, -0.03, 0.55), (-0.5, 2.0, 179.0)),
    ),
    "diagonal": (((3.4, 0.85, 0.95), (0.6, 2.0, 44.0)), ((-0.8, -0.88, 0.98), (-0.4, 2.5, -136.0))),
}
"""(xyz m, rpy deg) of the first and second LiDAR per mount preset (base_link: rear axle)."""


def _beam_geometry(beams: int) -> tuple[tuple[float, float], float]:
    """(vertical FOV deg, column width deg) of a class of spinning LiDAR by beam count.

    16: VLP-16-like (+-15 deg, 0.2 deg); 32: VLP-32C-like (-25..15, 0.2); up to 64:
    OS1-64 in 1024x10 mode (+-22.5 deg, 0.35 deg); more: OS1-128 in 512x10 mode (0.7 deg).
    """
    if beams <= 16:
        return (-15.0, 15.0), 0.2
    if beams <= 32:
        return (-25.0, 15.0), 0.2
    if beams <= 64:
        return (-22.5, 22.5), 0.35
    return (-22.5, 22.5), 0.7


def _sector_overlap_deg(a_center: float, a_width: float, b_center: float, b_width: float) -> float:
    """Angular overlap (deg) of two horizontal sectors given by centre and width."""
    gap = abs((a_center - b_center + 180.0) % 360.0 - 180.0)
    return max(0.0, (a_width + b_width) / 2.0 - gap)


def mount_preset(
    mount: MountPreset,
    beams: int = 32,
    *,
    range_noise_m: float = 0.01,
    rear_rotation_error_deg: float = 0.05,
    rear_translation_error_cm: float = 0.3,
    organized: tuple[bool, bool] = (False, False),
) -> list[LidarSimConfig]:
    """Two LiDARs with 120 deg views (non-overlapping) at one of the `MountPreset` places.

    The second LiDAR's recorded extrinsic is off by `rear_rotation_error_deg` /
    `rear_translation_error_cm`; `organized` picks the cloud layout of each.
    """
    vfov_deg, res_deg = _beam_geometry(beams)
    names = {
        "roof_front_rear": ("front", "rear"),
        "roof_left_right": ("left", "right"),
        "bumper_front_rear": ("front", "rear"),
        "diagonal": ("front_left", "rear_right"),
    }[mount]
    out = []
    for i, ((xyz, rpy), name) in enumerate(zip(_MOUNTS[mount], names, strict=True)):
        out.append(
            LidarSimConfig(
                name=name,
                beams=beams,
                horizontal_fov_deg=120.0,
                vertical_fov_deg=vfov_deg,
                horizontal_resolution_deg=res_deg,
                range_noise_m=range_noise_m,
                mount_xyz_m=xyz,
                mount_rpy_deg=rpy,
                recorded_rotation_error_deg=rear_rotation_error_deg if i else 0.0,
                recorded_translation_error_cm=rear_translation_error_cm if i else 0.0,
                organized=organized[i],
            )
        )
    return out


class CalibSceneConfig(ConfigModel):
    """A simulated calibration session: turntable (pure turns about a pivot) or drive.

    drive: the vehicle turns `turn_deg_range` and moves `translation_m_range` along an
    arc between stops, taking `moving_scans_range` sweeps to do it (motion-distorted
    scans), and stands still for `stop_duration_s_range` at each stop.
    """

    seed: int = 0
    motion: Literal["turntable", "drive"] = "turntable"
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
    turn_deg_range: tuple[float, float] = (25.0, 45.0)
    translation_m_range: tuple[float, float] = (0.3, 1.1)
    moving_scans_range: tuple[int, int] = (10, 18)
    stop_duration_s_range: tuple[float, float] = (0.45, 0.8)
    tf_chain: Literal["direct", "sensor_kit"] = "direct"
    """direct: base_link -> lidar on /tf_static; sensor_kit: base_link -> sensor_kit_frame
    -> lidar (two levels, as Autoware's sensor kits publish them)."""
    sensor_kit_frame: str = Field(default="sensor_kit_base_link", min_length=1)
    odometry: Literal["none", "odometry", "tf", "both"] = "none"
    """Wheel/IMU odometry of the vehicle: nav_msgs/Odometry on `odom_topic`, /tf
    odom -> base_link, or both (50 Hz, with scale error, yaw drift and noise)."""
    odom_topic: str = "/odom"
    odom_rate_hz: float = Field(default=50.0, gt=0.0, le=1000.0)
    odom_scale_error: float = Field(default=0.01, ge=0.0, le=0.2)
    """Standard deviation of the odometry's distance scale error (fraction)."""
    odom_yaw_scale_error: float = Field(default=0.01, ge=0.0, le=0.2)
    odom_noise_m: float = Field(default=0.002, ge=0.0, le=0.5)
    odom_noise_deg: float = Field(default=0.05, ge=0.0, le=10.0)

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
        for name in ("turn_deg_range", "translation_m_range", "stop_duration_s_range"):
            lo, hi = getattr(self, name)
            if not 0.0 <= lo <= hi:
                raise ValueError(f"{name} must be (low, high) with 0 <= low <= high")
        if not 1 <= self.moving_scans_range[0] <= self.moving_scans_range[1]:
            raise ValueError("moving_scans_range must be (low, high) with 1 <= low <= high")
        if self.motion == "drive" and self.stop_duration_s_range[0] < 2.0 * self.scan_period_s:
            raise ValueError("stop_duration_s_range must hold at least two scan periods")
        if self.turning_scans > 0 and self.scans_per_stop < 2:
            raise ValueError("turning_scans need scans_per_stop >= 2 so stops can be told apart")
        return self

    @property
    def step_deg(self) -> float:
        """Turntable angle between consecutive stops."""
        if math.isclose(self.sweep_deg, 360.0):
            return self.sweep_deg / self.n_stops
        return self.sweep_deg / (self.n_stops - 1)


def calib_scene_config(
    *,
    beams: int = 32,
    mount: MountPreset = DEFAULT_MOUNT,
    motion: Literal["turntable", "drive"] = "turntable",
    n_stops: int = 12,
    seed: int = 0,
    organized: Literal["none", "second", "both"] = "none",
    tf_chain: Literal["direct", "sensor_kit"] = "direct",
    odometry: Literal["none", "odometry", "tf", "both"] = "none",
    scene: SceneKind = "yard",
    range_noise_m: float = 0.01,
    rear_rotation_error_deg: float = 0.05,
    rear_translation_error_cm: float = 0.3,
) -> CalibSceneConfig:
    """A session from a few choices (what `simulate calib` exposes).

    drive sessions get a wider clear area (the vehicle's own sweep) and 3+ static scans per
    stop; turntable sessions keep one scan per stop as before.
    """
    lidars = mount_preset(
        mount,
        beams,
        range_noise_m=range_noise_m,
        rear_rotation_error_deg=rear_rotation_error_deg,
        rear_translation_error_cm=rear_translation_error_cm,
        organized=(organized == "both", organized in ("second", "both")),
    )
    if scene.startswith("parking"):
        scene_config = SceneConfig(kind=scene, yard_size_m=(60.0, 40.0), clear_radius_m=4.0)
    elif motion == "drive":
        scene_config = SceneConfig(kind=scene, yard_size_m=(30.0, 24.0), clear_radius_m=6.0)
    else:
        scene_config = SceneConfig(kind=scene)
    # The facing lot keeps the vehicle's heading within ~130 deg of its start over 12 stops.
    path = {"turn_deg_range": (8.0, 16.0)} if scene == "parking_lot_facing" else {}
    return CalibSceneConfig(
        seed=seed,
        motion=motion,
        n_stops=n_stops,
        scene=scene_config,
        lidars=lidars,
        tf_chain=tf_chain,
        odometry=odometry,
        **path,
    )
