"""Rig configuration: which topics hold what, where each camera looks, and the thresholds.

Loaded from YAML, TOML or JSON by `syncaudit.config` and validated by pydantic;
`schemas/rig.schema.json` is its JSON schema. Every number is finite and ranged. Angles are degrees; latencies microseconds (`_us`) as people write them in
configs; the analysis converts to int64 nanoseconds.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator

from syncaudit.config import ConfigModel, mapping_from_text, read_text, validate_mapping
from syncaudit.errors import ConfigError

StampSemantics = Literal["exposure_start", "exposure_middle", "exposure_end", "trigger"]

CAMERA_TOPIC_KEYS = ("image_topic", "info_topic", "exposure_topic", "trigger_topic")
"""The camera fields naming a topic; cameras may share one (told apart by frame_id)."""

MAX_LATENCY_US = 10_000_000.0
"""Largest latency, exposure or error limit a rig may state (10 s): anything above is a typo."""

_Strict = ConfigModel


class LidarConfig(_Strict):
    """The spinning LiDAR whose zero crossing triggers the cameras."""

    topic: str
    vendor: Literal["velodyne", "hesai", "ouster"] | None = None
    """Detected from the message type and packets when omitted."""
    metadata_topic: str | None = None
    """Ouster only: the std_msgs/String topic with the sensor metadata JSON."""
    time_field: str | None = None
    """PointCloud2 topics only: the per-point time field (default: the first of time, t,
    time_stamp, offset_time, timestamp present; see docs/clouds.md)."""
    stamp_marks: Literal["first", "last"] | None = None
    """PointCloud2 topics only: the point a cloud's header stamp marks where per-point
    times are relative and >= 0 (default 'first': times count from the stamp)."""
    model: str | None = None
    """Velodyne only: the model, where the product byte cannot tell (early VLP-16s write the
    HDL-32E's id 0x21); detected from the product byte and packet cadence when omitted."""
    zero_azimuth_deg: float = Field(0.0, ge=0.0, lt=360.0)
    """Packet azimuth at which a revolution starts and the trigger chain fires."""
    azimuth_increases: bool = True
    """True where the packet azimuth grows as the head spins (Velodyne, Hesai, Ouster)."""
    azimuth_of_x_axis_deg: float | None = Field(None, ge=0.0, lt=360.0)
    """Packet azimuth of the LiDAR frame's +X axis; used to turn camera yaws into azimuths."""
    azimuth_clockwise_from_above: bool = True
    """Whether packet azimuth grows clockwise seen from above (to convert yaws)."""


class CameraConfig(_Strict):
    """One camera triggered from the LiDAR."""

    name: str = Field(min_length=1)
    image_topic: str | None = None
    info_topic: str | None = None
    exposure_topic: str | None = None
    """CameraExposure, flir ImageMetaData or WFOVImage topic."""
    trigger_topic: str | None = None
    """TriggerEvent, builtin_interfaces/Time or sensor_msgs/TimeReference topic."""
    azimuth_deg: float | None = Field(None, ge=0.0, lt=360.0)
    """Centre of the HFOV as a packet azimuth of the LiDAR (what theta is measured in)."""
    yaw_deg: float | None = Field(None, ge=-360.0, le=360.0)
    """Centre of the HFOV as a yaw in the LiDAR frame (CCW from +X); converted to azimuth."""
    frame_id: str | None = None
    """The header.frame_id of the camera's messages (its optical frame, REP 103): tells its
    messages from other cameras' on a topic they share, and names its frame in /tf_static
    (where the yaw is taken from when the rig gives no angle)."""
    hfov_deg: float = Field(90.0, gt=0.0, le=360.0)
    stamp: StampSemantics = "exposure_start"
    """What the header stamp of the camera's images (and of exposure metadata without an
    explicit start: flir ImageMetaData, WFOVImage) marks. Drivers differ:
    'exposure_start' (the default: the sensor's start-of-exposure timestamp, what the
    method's checkpoint 248 is), 'exposure_middle' (NVIDIA DriveWorks' moeTimestampUs;
    ntnu-arl's blackfly_nodelet: its end-of-exposure event less half the exposure),
    'exposure_end' (FlyCapture's 1394 cycle time, latched when the shutter closes),
    'trigger' (the trigger reaching the camera, checkpoint 246; the exposure starts t4
    later: the trigger record's 248, else analysis.assumed_t4_us). A driver stamping on
    arrival at the host (spinnaker_camera_driver without adjust_timestamp) has none of
    these: give it exposure metadata with a start, or expect errors of the readout time."""
    assumed_exposure_us: float | None = Field(None, gt=0.0, le=MAX_LATENCY_US)
    """Exposure to assume where the log has no exposure metadata (marked as assumed)."""
    optional: bool = False
    """An optional camera that cannot be judged (too few paired frames) does not fail the
    gate; a required one does."""
    readout_us: float | None = Field(None, gt=0.0, le=MAX_LATENCY_US)
    """Rolling shutter: first row's start to last row's start (rows x row time); the
    exposure start the log gives is the top row's."""
    row_time_us: float | None = Field(None, gt=0.0, le=MAX_LATENCY_US)
    """Rolling shutter: one row's delay after the previous (needs `rows`)."""
    rows: int | None = Field(None, ge=1, le=100_000)
    """Image rows (for `row_time_us` or the per-row errors)."""
    lidar_row: int | None = Field(None, ge=0, le=100_000)
    """The row the LiDAR must meet at the camera's azimuth centre (default: the centre row)."""

    @model_validator(mode="after")
    def _rows_for_row_time(self) -> CameraConfig:
        if self.row_time_us is not None and self.rows is None:
            raise ValueError(f"camera {self.name!r}: row_time_us needs rows")
        if self.lidar_row is not None and self.rows is not None and self.lidar_row >= self.rows:
            raise ValueError(f"camera {self.name!r}: lidar_row must be below rows")
        return self


class Thresholds(_Strict):
    """Limits of the self-adaptive method; crossing either asks for a delay correction."""

    error_mean_us: float = Field(250.0, gt=0.0, le=MAX_LATENCY_US)
    """Eq. 5 limit. Default 250 us = 0.9 deg of rotation at 600 rpm; ordinary trigger-chain
    jitter of tens of microseconds stays well below it, so only a real bias crosses it."""
    error_var_us2: float = Field(40_000.0, gt=0.0, le=MAX_LATENCY_US**2)
    """Eq. 6 limit. Default (200 us)^2: the variance of |error| under jitter of std s is
    about 0.36 s^2, so this is crossed by instability, not by ordinary jitter."""
    min_paired_frames: int = Field(20, ge=1)
    """A camera with fewer frames paired with the LiDAR is not judged: Eq. 5/6 over a
    handful of frames say nothing (20 frames = 2 s at 10 Hz, two windows of Eq. 3)."""
    min_paired_fraction: float = Field(0.5, ge=0.0, le=1.0)
    """...nor one with fewer than this share of its frames paired: a verdict on the few
    frames that paired would hide why the rest did not."""


class AnalysisConfig(_Strict):
    """How the analysis averages and what it assumes where the log is silent."""

    window_frames: int = Field(10, ge=2, le=100_000)
    """N of Eq. 3, 5 and 6 (running exposure average and rolling error statistics)."""
    assumed_t2_us: float | None = Field(None, ge=0.0, le=MAX_LATENCY_US)
    assumed_t3_us: float | None = Field(None, ge=0.0, le=MAX_LATENCY_US)
    assumed_t4_us: float | None = Field(None, ge=0.0, le=MAX_LATENCY_US)
    clock_sync_tolerance_ms: float = Field(50.0, gt=0.0, le=MAX_LATENCY_US / 1000.0)
    """Median driver-minus-sensor time above this (or below -1 ms) = clocks not synchronised."""
    correction: Literal["recompute", "shift"] = "recompute"


TriggerDesign = Literal["lidar_packet", "ptp_phase", "lidar_sync_output", "free_running"]
"""How the cameras are triggered (docs/trigger-designs.md): from the LiDAR's packets after a
delay (the method's chain), at a phase of PTP time (TIER IV sensor_trigger), by the LiDAR's
sync output pulse, or not at all (free-running)."""


class TriggerConfig(_Strict):
    """The rig's trigger design, where the user states it (else the audit recognises it)."""

    design: TriggerDesign | None = None
    lidar_phase_lock_deg: float | None = Field(None, ge=0.0, lt=360.0)
    """Packet azimuth the LiDAR is phase-locked to cross at the top of each second
    (Velodyne phase lock, Hesai sync angle, Ouster phase_lock_offset / 1000)."""
    sync_output_angle_deg: float | None = Field(None, ge=0.0, lt=360.0)
    """lidar_sync_output: the azimuth at which the LiDAR emits its pulse (Ouster
    sync_pulse_out_angle); without it the correction is a trigger delay."""


class Rig(_Strict):
    """A whole rig: one triggering LiDAR, its cameras, thresholds and analysis settings."""

    lidar: LidarConfig
    cameras: list[CameraConfig] = Field(default_factory=list)
    thresholds: Thresholds = Field(default_factory=Thresholds)
    analysis: AnalysisConfig = Field(default_factory=AnalysisConfig)
    trigger: TriggerConfig = Field(default_factory=TriggerConfig)

    @model_validator(mode="after")
    def _unique_names(self) -> Rig:
        names = [c.name for c in self.cameras]
        if len(names) != len(set(names)):
            raise ValueError(f"camera names must be unique, got {names}")
        return self

    @model_validator(mode="after")
    def _shared_topics_tell_cameras_apart(self) -> Rig:
        """Cameras reading one topic need different frame_ids to tell their messages apart."""
        for key in CAMERA_TOPIC_KEYS:
            by_topic: dict[str, list[CameraConfig]] = {}
            for cam in self.cameras:
                topic = getattr(cam, key)
                if topic:
                    by_topic.setdefault(topic, []).append(cam)
            for topic, cams in by_topic.items():
                seen: dict[str, str] = {}
                for cam in cams:
                    if cam.frame_id is None:
                        continue
                    frame = cam.frame_id.lstrip("/")  # ROS 1 "/cam" is tf2's "cam"
                    if frame in seen:
                        raise ValueError(
                            f"cameras {seen[frame]!r} and {cam.name!r} share {key} "
                            f"{topic} and frame_id {cam.frame_id!r}: their messages cannot "
                            "be told apart; give each the header.frame_id its messages carry"
                        )
                    seen[frame] = cam.name
        return self


def load_rig(path: str | Path) -> Rig:
    """Read and validate a rig file (.yaml/.yml/.toml/.json).

    Raises:
        ConfigError: naming the file and the first bad key (with the nearest known key for
            a typo), for unreadable, oversized, non-UTF-8, too deeply nested or invalid rigs.
    """
    path = Path(path)
    return rig_from_text(read_text(path, what="rig file"), path)


def rig_from_text(text: str, path: str | Path) -> Rig:
    """Validate a rig's text read from `path` (a file or a URL: its suffix names the
    format); ConfigError as `load_rig`."""
    raw = mapping_from_text(text, path, what="rig file")
    if "lidar" not in raw:
        raise ConfigError(f"{path}: a rig file needs a 'lidar' mapping (with its 'topic')")
    return validate_mapping(path, raw, Rig, what="rig file")


def rig_json_schema() -> dict[str, object]:
    """The JSON schema of rig files, as exported to schemas/rig.schema.json."""
    return Rig.model_json_schema()
