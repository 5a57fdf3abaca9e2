"""Simulated drive logs with known LiDAR-camera synchronisation truth.

One host clock is true time. A spinning LiDAR (Velodyne VLP-16/VLP-32C/VLS-128, Hesai
Pandar40P/PandarXT32) turns at a nominal RPM with a slow sinusoidal rate drift; its azimuth
is the exact integral of the angular velocity. Packets follow the model's real firing clock
(the vendor modules' packet period and block timing rules), each block carrying the
azimuth at its firing time (the VLS-128's four banks share their sequence's start), and are
encoded as real vendor packets. Each packet reaches the LiDAR driver t1 after capture; a
fraction is lost on the network (never written, never seen by the driver). Packets are
published one scan message per revolution, cut at the zero-crossing packet (the first
delivered packet with a block at or past the zero azimuth).

Cameras are triggered from that packet through the chain of the method (part A of
docs/method.md): 240 packet capture -> t1 -> 242 LiDAR driver -> t2 -> 244 camera driver
-> applied delay + t3 -> 246 camera sensor -> t4 -> 248 exposure start, exposure t5_i.
The truth of every frame is exact integer arithmetic on those times:

    t_l = exposure_start + t5_i / 2                      (t5_i is an even number of ns)
    t_estimated = time at which the true azimuth equals zero + theta in that revolution
    error = t_l - t_estimated                            (signed; Eq. 4 is |error|)
    ideal_delay = t_estimated - (lidar_packet + t1 + t2 + t3 + t4 + t5_i / 2)
    error = applied_delay - ideal_delay

The sensor clock is true time + `clock_offset_ns`; packet stamps are whole microseconds of
the sensor clock (as the packets hold them), so what the log implies is exactly the truth
apart from the 0.01 deg azimuth quantisation of the packets.
"""

from __future__ import annotations

import heapq
import json
import math
import struct
import typing
import zlib
from collections.abc import Callable, Iterator, Mapping
from dataclasses import asdict, dataclass
from functools import partial
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field, model_validator

from syncaudit.config import ConfigModel
from syncaudit.errors import ConfigError
from syncaudit.lidar.hesai import HESAI_LAYOUTS, RosHeader, returns_per_firing
from syncaudit.lidar.hesai_encode import build_pandar_scan, encode_hesai
from syncaudit.lidar.velodyne import HOUR_US, RETURN_STRONGEST, velodyne_firing_offsets_ns
from syncaudit.lidar.velodyne_encode import (
    build_velodyne_scan,
    encode_velodyne,
    velodyne_revolution_schedule,
)
from syncaudit.simulate import LidarModel, ouster_packets
from syncaudit.simulate.cloud_writer import CloudConvention, cloud_message, cloud_points
from syncaudit.simulate.delays import (
    CONSTANT_WINDOW_FRAMES,
    CameraDelays,
    CompensatedDelays,
    FrameTiming,
    LiveDelays,
)
from syncaudit.simulate.ouster_packets import OusterProfile
from syncaudit.simulate.trigger_designs import (
    DesignTimes,
    SlippingRotation,
    TriggerDesignSim,
    design_times,
    locked_start_deg,
    newton_time_ns,
)
from syncaudit.writers.log_writer import BagCompression, LogFormat, LogWriter, open_writer
from syncaudit.writers.outputs import OutputSet
from syncaudit.writers.provenance import marked_json

StampSemantics = Literal["exposure_start", "exposure_middle", "exposure_end", "trigger"]
TriggerPacket = Literal["containing", "first_after"]
"""Which packet a trigger fires from (and names in `TriggerEvent.lidar_packet_time`).

'containing': the packet that holds the zero crossing (its first block at or past zero
with a block before it, or the first block exactly at zero): what a driver tracking the
azimuth block by block sees first. 'first_after': the first packet whose first block is
at or past zero, what a driver that cuts revolutions packet by packet sees first (the next
packet in most revolutions). `trigger_packet_offset` moves either by whole packets."""
ExposureMessage = Literal["camera_exposure", "flir_meta"]
TriggerMessage = Literal["trigger_event", "time_reference"]
"""The trigger record of each frame: 'trigger_event' (syncaudit_msgs/TriggerEvent, the five
checkpoints, the camera's frame counter in `frame_sequence`) or 'time_reference'
(sensor_msgs/TimeReference, as trigger boards publish: only when the trigger reached the
camera, 246, in `time_ref`, and in ROS 1 the publisher's header seq as its only number)."""
CameraTopicKind = Literal["image", "exposure", "meta", "trigger"]
"""The kinds of per-frame camera message the simulator writes (one topic each per camera,
or one topic shared by every camera: see `SyncSimConfig.shared_topics`)."""
SHARED_TOPICS: dict[str, str] = {
    "image": "/cameras/image_raw",
    "exposure": "/cameras/exposure",
    "meta": "/cameras/meta",
    "trigger": "/cameras/trigger",
}
"""Topic of each kind that all cameras share when the kind is in `shared_topics` (a
compressed image topic gets `/compressed` appended)."""

NS_PER_S = 1_000_000_000
NS_PER_US = 1_000
HESAI_RETURN_STRONGEST = 0x37
FLIR_MAX_EXPOSURE_US = 20_000
"""`ImageMetaData.max_exposure_time` the simulated cameras report."""

_VENDOR_OF: dict[str, str] = {
    "VLP-16": "velodyne",
    "VLP-32C": "velodyne",
    "VLS-128": "velodyne",
    "Pandar40P": "hesai",
    "PandarXT32": "hesai",
    "PandarXT32M": "hesai",
    "Pandar128E4X": "hesai",
    "OS-1-64": "ouster",
}
_HESAI_RETURN_MODE: dict[str, int] = {"PandarXT32M": 0x3C}
"""Tail return mode written per Hesai model (else strongest): the XT32M in the dual
first + strongest mode of the real capture, 3 firings x 2 returns per packet."""
_VELODYNE_BLOCKS_PER_AZIMUTH: dict[str, int] = {"VLP-16": 1, "VLP-32C": 1, "VLS-128": 4}
"""Consecutive blocks that carry one azimuth sample: the VLS-128's four banks (0xEEFF ..
0xBBFF) share the azimuth sampled when their 53.3 us firing sequence starts."""
JPEG_FORMAT = "jpeg"
"""`CompressedImage.format` of the JPEG-like payloads written when `image_bytes` is set."""
CLOUD_TOPIC = "/points"
_X_AXIS_AZIMUTH_DEG: dict[str, float] = {"velodyne": 0.0, "hesai": 90.0, "ouster": 180.0}
"""Packet azimuth of the LiDAR frame's +X axis in the vendors' ROS drivers: Velodyne
x = r cos(az), y = -r sin(az); Hesai x = r sin(az), y = r cos(az). Both grow clockwise.
Ouster: the mounts are given in the sensor frame (ouster-ros' os_sensor), which the Ouster
manual turns 180 deg about z from the lidar frame whose +X is at encoder angle 0."""


# ==================================================================================== config


_Strict = ConfigModel


class LatencyDist(_Strict):
    """A positive latency: `min_us` plus a lognormal part with the given mean and std.

    Lognormal because network and scheduling latencies are positive and right-skewed; the
    total mean and std are `mean_us` and `std_us` (std 0 = constant).
    """

    mean_us: float = Field(gt=0.0)
    std_us: float = Field(default=0.0, ge=0.0)
    min_us: float = Field(default=0.0, ge=0.0)

    @model_validator(mode="after")
    def _min_below_mean(self) -> LatencyDist:
        if self.min_us >= self.mean_us:
            raise ValueError("min_us must be below mean_us")
        return self

    def draw_ns(self, rng: np.random.Generator, n: int) -> NDArray[np.int64]:
        """n latencies in integer nanoseconds."""
        excess = (self.mean_us - self.min_us) * NS_PER_US
        if self.std_us == 0.0:
            values = np.full(n, excess)
        else:
            sigma2 = math.log1p((self.std_us * NS_PER_US / excess) ** 2)
            mu = math.log(excess) - sigma2 / 2.0
            values = rng.lognormal(mu, math.sqrt(sigma2), n)
        return np.rint(values + self.min_us * NS_PER_US).astype(np.int64)


class LightModel(_Strict):
    """Exposure driven by the light: bright -> tunnel -> bright, with smooth transitions.

    Auto exposure moves each frame a fraction `ae_gain` of the way to the target
    (cameras lag the light by a few frames), then multiplicative noise is applied.
    """

    bright_exposure_us: float = Field(default=2_000.0, gt=0.0)
    dark_exposure_us: float = Field(default=12_000.0, gt=0.0)
    tunnel_start_s: float | None = None
    """Start of the transition into the tunnel, from the log start; None: 35 % of it."""
    tunnel_length_s: float | None = None
    """From entering to leaving the tunnel; None: 30 % of the log."""
    transition_s: float = Field(default=2.0, gt=0.0)
    ae_gain: float = Field(default=0.5, gt=0.0, le=1.0)
    noise_frac: float = Field(default=0.02, ge=0.0, lt=0.5)


class CameraSim(_Strict):
    """One simulated camera."""

    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_]+$")
    yaw_deg: float
    """Viewing direction in the LiDAR frame, counter-clockwise from +X (REP 103)."""
    hfov_deg: float = Field(default=90.0, gt=0.0, le=360.0)
    stamp_semantics: StampSemantics = "exposure_start"
    """What the image header stamp marks ('trigger': 246, the trigger reaching the camera)."""
    delay_error_us: float = 0.0
    """Offset of the (initial) applied delay from the log's true ideal delay."""


class ExtraLidarSim(_Strict):
    """Another spinning LiDAR on the vehicle, recorded beside the trigger LiDAR: its packets
    only (no camera fires from it), as fleets record a rear or side LiDAR."""

    model: LidarModel
    topic: str = Field(pattern=r"^/[A-Za-z0-9_/]+$")
    frame_id: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_]+$")
    rpm: float = Field(default=600.0, ge=300.0, le=1200.0)
    start_azimuth_deg: float = Field(default=0.0, ge=0.0, lt=360.0)

    @model_validator(mode="after")
    def _check(self) -> ExtraLidarSim:
        if _VENDOR_OF[self.model] == "ouster":
            raise ValueError("an extra LiDAR is a Velodyne or Hesai model (packet scans)")
        return self


def _default_cameras() -> list[CameraSim]:
    return [
        CameraSim(name="front", yaw_deg=0.0),
        CameraSim(name="rear_left", yaw_deg=120.0),
        CameraSim(name="rear_right", yaw_deg=240.0),
    ]


class SyncSimConfig(_Strict):
    """Everything `simulate_sync_log` needs; defaults give a 10 s VLP-16 log, 3 cameras."""

    seed: int = 0
    duration_s: float = Field(default=10.0, gt=0.0, le=4 * 3_600.0)
    """Up to four hours. Memory grows with it (the packet arrays are built whole): a dense
    log (VLS-128 + VLP-32C, six cameras) took 7.5 GB for one hour, 14.9 GB for two."""
    start_time_ns: int = Field(default=1_700_000_000 * NS_PER_S, gt=0)
    """True (host) time of the log start."""
    log_format: LogFormat = "mcap"
    bag_compression: BagCompression = "none"
    """ROS 1 bags: chunk compression (lz4 or bz2, as `rosbag record --lz4` / `--bz2`)."""
    overwrite: bool = False

    lidar_model: LidarModel = "VLP-16"
    rpm: float = Field(default=600.0, ge=300.0, le=1200.0)
    rpm_drift_frac: float = Field(default=0.005, ge=0.0, lt=0.2)
    """Amplitude of the sinusoidal rate drift, as a fraction of the nominal rate."""
    rpm_drift_period_s: float = Field(default=30.0, gt=0.0)
    rpm_drift_phase_deg: float = 0.0
    start_azimuth_deg: float = Field(default=123.45, ge=0.0, lt=360.0)
    """Azimuth of the head at the log start."""
    zero_azimuth_deg: float | None = Field(default=None, ge=0.0, lt=360.0)
    """Packet azimuth of the zero crossing; None: 60 deg before the first camera's centre,
    so every camera's t_rotate exceeds the trigger chain."""
    azimuth_of_x_axis_deg: float | None = Field(default=None, ge=0.0, lt=360.0)
    """Packet azimuth of the LiDAR frame's +X axis; None: the vendor driver's convention."""
    clock_offset_ns: int = 0
    """Sensor clock minus host clock (0 = synchronised; 1_531 s mimics the VLP-16 sample).
    Velodyne packets hold microseconds past the hour, so offsets beyond +-30 min cannot be
    told from an hour error by a reader."""
    packet_drop_fraction: float = Field(default=0.001, ge=0.0, lt=0.5)
    lidar_returns: Literal["smooth", "random"] = "smooth"
    """'smooth': ranges of a simple room (compress well); 'random': noise ranges."""
    lidar_frame: str = "lidar_top"
    cloud_convention: CloudConvention | None = None
    """Also write the LiDAR as sensor_msgs/PointCloud2 on /points, one cloud per scan, in
    this field convention (`simulate.cloud_writer`), from the same firing times."""
    cloud_beams: int = Field(default=16, ge=1, le=256)
    """Points per block in the clouds (one per beam): 32 with a VLS-128 gives its ~240k
    points per revolution at 600 rpm."""
    lidar_packets: bool = True
    """Write the packet topic (False with a cloud_convention: a cloud-only log)."""
    ouster_profile: OusterProfile = "RNG19_RFL8_SIG16_NIR16"
    """Ouster models: the UDP profile of the packets (and of the metadata written)."""

    t1: LatencyDist = LatencyDist(mean_us=300.0, std_us=40.0, min_us=150.0)
    """240 -> 242 per packet: network to the LiDAR driver."""
    t2: LatencyDist = LatencyDist(mean_us=60.0, std_us=15.0, min_us=20.0)
    """242 -> 244 per trigger: shared memory write + read."""
    t3: LatencyDist = LatencyDist(mean_us=120.0, std_us=20.0, min_us=50.0)
    """244 -> 246 per trigger (after the delay): trigger line / GPIO to the camera."""
    t4: LatencyDist = LatencyDist(mean_us=40.0, std_us=5.0, min_us=20.0)
    """246 -> 248 per trigger: sensor start-of-exposure latency."""
    image_latency: LatencyDist = LatencyDist(mean_us=8_000.0, std_us=500.0, min_us=5_000.0)
    """Exposure end -> image published (readout, transfer, debayer)."""

    light: LightModel = LightModel()
    cameras: list[CameraSim] = Field(default_factory=_default_cameras, min_length=1)
    image_kind: Literal["raw", "compressed"] = "raw"
    image_bytes: int | None = Field(default=None, ge=64, le=64 * 1024 * 1024)
    """CompressedImage payload size in bytes (needs image_kind 'compressed'): JPEG-like
    incompressible bytes framed by SOI/EOI, format 'jpeg', the size of a real camera's
    frames (250-400 KB for 1080p). None: a tiny PNG of the simulated scene."""
    exposure_messages: tuple[ExposureMessage, ...] = ("camera_exposure", "flir_meta")
    trigger_messages: bool = True
    trigger_message: TriggerMessage = "trigger_event"
    """The trigger record written (see `TriggerMessage`)."""
    ros1_header_seq: bool = True
    """ROS 1 logs: number each camera's header `seq` by frame; False writes 0 everywhere,
    as drivers that leave it alone and bags converted from ROS 2 do."""
    shared_topics: tuple[CameraTopicKind, ...] = ()
    """Kinds of camera message that every camera publishes on one topic (`SHARED_TOPICS`),
    as one driver node for several cameras does, told apart only by header.frame_id (and
    the `camera` field of the syncaudit types while `camera_field` is set). ROS 1 header
    seq numbers on a shared topic count that topic's messages, as one publisher does."""
    header_frame_ids: bool = True
    """Write each camera's optical frame in header.frame_id; False leaves it empty, as
    drivers that never set it do (/tf_static still names the frames)."""
    camera_field: bool = True
    """Write the rig camera name in CameraExposure/TriggerEvent.camera; False leaves it
    empty, so that header.frame_id is the only field telling cameras apart."""
    trigger_packet: TriggerPacket = "containing"
    """The packet convention of the triggers (see `TriggerPacket`)."""
    trigger_packet_offset: int = Field(default=0, ge=-32, le=32)
    """Triggers fire from the packet this many delivered packets after (negative: before)
    the one `trigger_packet` picks: a driver that waits for, or predicts, the crossing."""
    trigger_design: TriggerDesignSim | None = None
    """Trigger the cameras by another design than the chain (`simulate.trigger_designs`):
    bare `builtin_interfaces/Time` trigger records, or none for free-running cameras."""
    extra_lidars: list[ExtraLidarSim] = Field(default_factory=list, max_length=8)
    """More LiDARs whose packet scans the log records on their own topics (the truth's
    `extra_lidars`; the rig names only the trigger LiDAR)."""

    @model_validator(mode="after")
    def _check(self) -> SyncSimConfig:
        names = [c.name for c in self.cameras]
        if len(set(names)) != len(names):
            raise ValueError(f"camera names must be unique: {names}")
        if len(set(self.exposure_messages)) != len(self.exposure_messages):
            raise ValueError("exposure_messages has duplicates")
        if len(set(self.shared_topics)) != len(self.shared_topics):
            raise ValueError("shared_topics has duplicates")
        if self.image_bytes is not None and self.image_kind != "compressed":
            raise ValueError("image_bytes needs image_kind 'compressed'")
        if self.vendor == "ouster":
            ouster_packets.columns_per_frame(self.rpm)  # 600 or 1200 RPM (lidar_mode)
        topics = [e.topic for e in self.extra_lidars]
        if len(set(topics)) != len(topics) or {"/velodyne_packets", "/pandar_packets"} & set(
            topics
        ):
            raise ValueError(f"extra LiDAR topics must be unique and not the trigger's: {topics}")
        return self

    @property
    def vendor(self) -> str:
        """'velodyne' or 'hesai'."""
        return _VENDOR_OF[self.lidar_model]


# ================================================================================== rotation


@dataclass(frozen=True, slots=True)
class Rotation:
    """Unwrapped azimuth A(t) = A0 + integral of omega, omega = w0 (1 + f sin(2 pi t/P + phi)).

    t is true time in ns relative to the log start (float64: sub-ns resolution over hours).
    """

    start_deg: float
    w0_deg_ns: float
    drift_frac: float
    period_ns: float
    phase_rad: float

    def angle_deg(self, t_ns: NDArray[np.float64]) -> NDArray[np.float64]:
        """Unwrapped azimuth (deg) at t."""
        k = 2.0 * math.pi / self.period_ns
        wobble = (np.cos(k * t_ns + self.phase_rad) - math.cos(self.phase_rad)) / k
        return self.start_deg + self.w0_deg_ns * (t_ns - self.drift_frac * wobble)

    def rate_deg_ns(self, t_ns: NDArray[np.float64]) -> NDArray[np.float64]:
        """Angular velocity (deg/ns) at t."""
        k = 2.0 * math.pi / self.period_ns
        return self.w0_deg_ns * (1.0 + self.drift_frac * np.sin(k * t_ns + self.phase_rad))

    def time_at_ns(self, angle_deg: NDArray[np.float64]) -> NDArray[np.float64]:
        """Solve A(t) = angle exactly (Newton; A is strictly increasing)."""
        target = np.asarray(angle_deg, dtype=np.float64)
        return newton_time_ns(self, target, (target - self.start_deg) / self.w0_deg_ns)


# ============================================================================ LiDAR packets


@dataclass(frozen=True, slots=True)
class _PacketClock:
    """Packet k's stamp = floor_us(T0 + (num * k) // den); blocks at stamp + offsets."""

    period_num_ns: int
    period_den: int
    block_offset_ns: NDArray[np.int64]
    azimuth_units_per_deg: int


def _packet_clock(model: str, rpm: float) -> _PacketClock:
    """The model's packet period and block sample offsets from the vendor modules."""
    if _VENDOR_OF[model] == "ouster":
        cols = ouster_packets.columns_per_frame(rpm)
        column_ns = 60 * NS_PER_S // (round(rpm) * cols)
        offsets = np.arange(ouster_packets.COLUMNS_PER_PACKET, dtype=np.int64) * column_ns
        # Azimuth units: `cols` per degree, so a column is 360 units exactly.
        return _PacketClock(int(offsets[-1] + column_ns), 1, offsets, cols)
    if _VENDOR_OF[model] == "velodyne":
        sched = velodyne_revolution_schedule(model, rpm, 0, n_packets=2)
        period = int(sched.packet_stamp_ns[1] - sched.packet_stamp_ns[0])
        first_firing = velodyne_firing_offsets_ns(model, False)[:, 0].astype(np.int64)
        # A block's azimuth is sampled at the first firing of the first block of its group.
        group = _VELODYNE_BLOCKS_PER_AZIMUTH[model]
        offsets = first_firing[(np.arange(first_firing.size) // group) * group]
        return _PacketClock(period, 1, offsets, 100)
    layout = HESAI_LAYOUTS[model]
    returns = returns_per_firing(_HESAI_RETURN_MODE.get(model, HESAI_RETURN_STRONGEST))
    offsets = layout.block_offset_ns(np.full(1, returns, dtype=np.int64))[0].astype(np.int64)
    return _PacketClock(
        layout.period_num_ns * (layout.n_blocks // returns),
        layout.period_den,
        offsets,
        layout.azimuth_units_per_deg,
    )


_PACKETS_PER_SLICE = 65_536
"""Packets per slice when computing azimuths (bounds the generator's memory)."""


@dataclass(frozen=True, slots=True)
class _Packets:
    """Every packet the sensor sent in the simulated span (delivered or not)."""

    stamp_sensor_ns: NDArray[np.int64]
    """(n,) packet time in the sensor clock, whole microseconds."""
    capture_ns: NDArray[np.int64]
    """(n,) the same instant in true (host) time: checkpoint 240."""
    block_true_ns: NDArray[np.int64] | None
    """(n, B) true time of each block's azimuth sample: Ouster's column stamps; None for
    Velodyne and Hesai, whose packets state only the packet's time (not kept: on a
    two-hour log it would be the simulator's largest array)."""
    azimuth_q: NDArray[np.int64]
    """(n, B) unwrapped block azimuth in the packet's units (0.01 deg)."""
    delivered: NDArray[np.bool_]
    t1_ns: NDArray[np.int64]
    driver_ns: NDArray[np.int64]
    """(n,) checkpoint 242: the driver's stamp of the packet."""


# ==================================================================================== truth


def _eq5_eq6(abs_error_ns: NDArray[np.int64]) -> tuple[float, float]:
    """Eq. 5 and Eq. 6 over all frames, exact integer sums (Eq. 6 literally rearranged)."""
    n = int(abs_error_ns.size)
    if n == 0:
        return math.nan, math.nan
    values = [int(v) for v in abs_error_ns]
    s1 = sum(values)
    s2 = sum(v * v for v in values)
    mean = s1 / n
    var = (n * s2 - s1 * s1) / (n * (n - 1)) if n > 1 else math.nan
    return mean, var


def _rows(columns: dict[str, NDArray[np.int64]]) -> list[dict[str, int]]:
    """Per-frame truth records (plain ints) from equal-length integer columns."""
    lists = {name: values.tolist() for name, values in columns.items()}
    n = len(next(iter(lists.values()))) if lists else 0
    return [{name: int(values[i]) for name, values in lists.items()} for i in range(n)]


def _smoothstep(x: NDArray[np.float64]) -> NDArray[np.float64]:
    return 0.5 - 0.5 * np.cos(np.pi * np.clip(x, 0.0, 1.0))


def _target_exposure_us(
    light: LightModel, t_s: NDArray[np.float64], duration_s: float
) -> NDArray[np.float64]:
    """Exposure the light asks for at t (s from the log start): log-space bright/dark blend."""
    start = light.tunnel_start_s if light.tunnel_start_s is not None else 0.35 * duration_s
    length = light.tunnel_length_s if light.tunnel_length_s is not None else 0.30 * duration_s
    dark = _smoothstep((t_s - start) / light.transition_s) * (
        1.0 - _smoothstep((t_s - start - length) / light.transition_s)
    )
    lo, hi = math.log(light.bright_exposure_us), math.log(light.dark_exposure_us)
    return np.exp(lo + dark * (hi - lo))


def _exposures_ns(
    light: LightModel, t_s: NDArray[np.float64], duration_s: float, rng: np.random.Generator
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Per frame: exposure t5_i (even ns) and the scene brightness relative to the bright
    light times the exposure (what the image shows, 1.0 = well exposed)."""
    target = _target_exposure_us(light, t_s, duration_s)
    out = np.empty_like(target)
    current = float(target[0]) if target.size else 0.0
    for i, goal in enumerate(target.tolist()):
        current += light.ae_gain * (goal - current)
        out[i] = current
    out *= 1.0 + light.noise_frac * rng.standard_normal(out.size)
    t5_ns = 2 * np.rint(out * NS_PER_US / 2.0).astype(np.int64)
    exposure_ratio = t5_ns / (target * NS_PER_US)
    return np.maximum(t5_ns, 2), exposure_ratio


# ================================================================================ messages


def _png_gray(pixels: NDArray[np.uint8]) -> bytes:
    """A minimal valid 8-bit grayscale PNG of a 2-D array."""

    def chunk(kind: bytes, body: bytes) -> bytes:
        crc = zlib.crc32(kind + body) & 0xFFFFFFFF
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc)

    height, width = pixels.shape
    raw = b"".join(b"\x00" + pixels[row].tobytes() for row in range(height))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(raw, 6))
        + chunk(b"IEND", b"")
    )


def _jpeg_like(size: int, seed: int) -> bytes:
    """`size` bytes that look like a JPEG to a reader and do not compress: SOI, a JFIF APP0
    segment, entropy-coded-like random bytes (no 0xFF, so no false markers), EOI."""
    head = b"\xff\xd8" + b"\xff\xe0\x00\x10JFIF\x00\x01\x01\x00\x00\x01\x00\x01\x00\x00"
    tail = b"\xff\xd9"
    body = np.frombuffer(np.random.default_rng(seed).bytes(size - len(head) - len(tail)), np.uint8)
    return head + np.minimum(body, np.uint8(0xFE)).tobytes() + tail


def _camera_quaternion(yaw_deg: float) -> tuple[float, float, float, float]:
    """Rotation (x, y, z, w) of an optical frame (z forward, x right, y down) at `yaw_deg`."""
    yaw = math.radians(yaw_deg)
    z_axis = (math.cos(yaw), math.sin(yaw), 0.0)
    x_axis = (math.sin(yaw), -math.cos(yaw), 0.0)
    y_axis = (0.0, 0.0, -1.0)
    m = [[x_axis[r], y_axis[r], z_axis[r]] for r in range(3)]
    trace = m[0][0] + m[1][1] + m[2][2]
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        return ((m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s, s / 4)
    if m[0][0] > m[1][1] and m[0][0] > m[2][2]:
        s = 2.0 * math.sqrt(1.0 + m[0][0] - m[1][1] - m[2][2])
        return (s / 4, (m[0][1] + m[1][0]) / s, (m[0][2] + m[2][0]) / s, (m[2][1] - m[1][2]) / s)
    if m[1][1] > m[2][2]:
        s = 2.0 * math.sqrt(1.0 + m[1][1] - m[0][0] - m[2][2])
        return ((m[0][1] + m[1][0]) / s, s / 4, (m[1][2] + m[2][1]) / s, (m[0][2] - m[2][0]) / s)
    s = 2.0 * math.sqrt(1.0 + m[2][2] - m[0][0] - m[1][1])
    return ((m[0][2] + m[2][0]) / s, (m[1][2] + m[2][1]) / s, s / 4, (m[1][0] - m[0][1]) / s)


@dataclass(frozen=True, slots=True)
class _Chain:
    """One camera's frames before the delay: when each should be exposed, and the chain."""

    n: int
    """Frames: one per whole revolution."""
    theta_deg: float
    """Rotation from the zero crossing to the camera's centre."""
    t_est: NDArray[np.int64]
    """When the beam points at the camera's centre (true time): the frame's target."""
    packet_ns: NDArray[np.int64]
    """Capture (240) of the packet the trigger fires from."""
    t1: NDArray[np.int64]
    t2: NDArray[np.int64]
    t3: NDArray[np.int64]
    t4: NDArray[np.int64]
    t5: NDArray[np.int64]
    """Exposure durations (even ns)."""
    exposure_ratio: NDArray[np.float64]
    ideal: NDArray[np.int64]
    """The delay that would put the exposure's middle at t_est."""


@dataclass(frozen=True, slots=True)
class _FrameTimes:
    """Step 3 of a camera: what the applied delays lead to, per frame (true time, ns)."""

    exposure_start: NDArray[np.int64]
    t_l: NDArray[np.int64]
    """Middle of the exposure."""
    error: NDArray[np.int64]
    """t_l - t_est (signed)."""
    stamp: NDArray[np.int64]
    """The image header stamp under the camera's stamp semantics."""


def _frame_times(
    chain: _Chain, applied: NDArray[np.int64], semantics: StampSemantics
) -> _FrameTimes:
    """Exposure start, middle, error and image stamp of every frame of a camera."""
    triggered = chain.packet_ns + chain.t1 + chain.t2 + applied + chain.t3
    exposure_start = triggered + chain.t4
    t_l = exposure_start + chain.t5 // 2
    stamp = {
        "exposure_start": exposure_start,
        "exposure_middle": exposure_start + chain.t5 // 2,
        "exposure_end": exposure_start + chain.t5,
        "trigger": triggered,
    }[semantics]
    return _FrameTimes(exposure_start, t_l, t_l - chain.t_est, stamp)


def _design_frame_times(
    chain: _Chain, design: DesignTimes, semantics: StampSemantics
) -> _FrameTimes:
    """Exposure start (top row), middle, error and image stamp under a trigger design."""
    start = design.exposure_start_ns
    t_l = start + chain.t5 // 2
    triggered = design.trigger_ns if design.trigger_ns is not None else start
    stamp = {
        "exposure_start": start,
        "exposure_middle": t_l,
        "exposure_end": start + chain.t5,
        "trigger": triggered,
    }[semantics]
    return _FrameTimes(start, t_l, t_l - chain.t_est, stamp)


def _design_truth(
    cfg: SyncSimConfig, index: int, design: DesignTimes, times: _FrameTimes
) -> dict[str, Any]:
    """The design's truth of one camera: settings, the shift that centres the target row's
    error, and the error at the top, target and bottom rows."""
    assert cfg.trigger_design is not None
    sim = cfg.trigger_design
    rows = sim.rows
    error = times.error.astype(np.float64)
    at_rows = {
        "top": float(error.mean()),
        "target": float((error + design.target_row_offset_ns).mean()),
        "bottom": float((error + design.row_time_ns * (rows - 1)).mean()),
    }
    target = error + design.target_row_offset_ns
    return {
        "design": sim.design,
        "lidar_phase_lock_deg": sim.lidar_phase_lock_deg,
        "setting": design.setting,
        "rows": rows,
        "row_time_ns": design.row_time_ns,
        "target_row": rows // 2 if design.row_time_ns else None,
        "error_signed_mean_ns_at_rows": at_rows,
        "true_shift_ns": -float(np.median(target)),
        "floor_ns": float(np.mean(np.abs(target - np.median(target)))),
        "delay_error_ns": round(cfg.cameras[index].delay_error_us * NS_PER_US),
    }


@dataclass(slots=True)
class _Outgoing:
    """Serialized messages waiting to be written in log-time order."""

    items: list[tuple[int, int, str, bytes | Callable[[], bytes]]]
    """(log time, order, topic, serialized bytes or a function making them when written:
    large image payloads are only built as they are written, so memory stays bounded)."""

    def add(self, log_time_ns: int, topic: str, data: bytes | Callable[[], bytes]) -> None:
        self.items.append((int(log_time_ns), len(self.items), topic, data))


# =============================================================================== simulator


def truth_path(out: Path) -> Path:
    """Where the truth of a simulated log is written: `<out>.truth.json`."""
    return Path(str(out) + ".truth.json")


class _Simulation:
    """One run of the simulator: arrays first (vectorised), then messages."""

    def __init__(
        self,
        config: SyncSimConfig,
        outputs: OutputSet,
        delays: LiveDelays | CompensatedDelays | None,
    ) -> None:
        self.cfg = config
        self.outputs = outputs
        self.delays = delays
        seeds = np.random.SeedSequence(config.seed).spawn(8)
        self.rng_drop, self.rng_t1, self.rng_points = (np.random.default_rng(s) for s in seeds[:3])
        self.camera_seeds = seeds[3]
        self.vendor = config.vendor
        self.x_axis_deg = (
            config.azimuth_of_x_axis_deg
            if config.azimuth_of_x_axis_deg is not None
            else _X_AXIS_AZIMUTH_DEG[self.vendor]
        )
        self.camera_azimuth_deg = [(self.x_axis_deg - c.yaw_deg) % 360.0 for c in config.cameras]
        self.zero_deg = (
            config.zero_azimuth_deg
            if config.zero_azimuth_deg is not None
            else round((self.camera_azimuth_deg[0] - 60.0) % 360.0, 2) % 360.0
        )
        self.rotation: Rotation | SlippingRotation = self._rotation(config)
        self.clock = _packet_clock(config.lidar_model, config.rpm)
        self.topic = {
            "velodyne": "/velodyne_packets",
            "hesai": "/pandar_packets",
            "ouster": "/ouster/lidar_packets",
        }[self.vendor]
        self.msgtype = {
            "velodyne": "velodyne_msgs/msg/VelodyneScan",
            "hesai": "pandar_msgs/msg/PandarScan",
            "ouster": "ouster_sensor_msgs/msg/PacketMsg",
        }[self.vendor]

    @staticmethod
    def _rotation(config: SyncSimConfig) -> Rotation | SlippingRotation:
        """The head's rotation; phase-locked (no drift, the lock azimuth at each top of
        second) and slipping out of lock as `trigger_design` says."""
        design = config.trigger_design
        w0 = config.rpm * 6.0 / NS_PER_S
        lock = None if design is None else design.lidar_phase_lock_deg
        base = Rotation(
            start_deg=config.start_azimuth_deg
            if lock is None
            else locked_start_deg(lock, w0, config.start_time_ns + config.clock_offset_ns),
            w0_deg_ns=w0,
            drift_frac=config.rpm_drift_frac if lock is None else 0.0,
            period_ns=config.rpm_drift_period_s * NS_PER_S,
            phase_rad=math.radians(config.rpm_drift_phase_deg),
        )
        if design is None or lock is None or design.lock_slip_start_s is None:
            return base
        return SlippingRotation(
            base,
            design.lock_slip_start_s * NS_PER_S,
            design.lock_slip_length_s * NS_PER_S,
            design.lock_slip_deg,
        )

    # -- LiDAR ----------------------------------------------------------------------------

    def packets(self) -> _Packets:
        """All packets of the span: firing clock, azimuths, drops, t1."""
        if self.vendor == "ouster":
            return self._ouster_packets()
        cfg, clk = self.cfg, self.clock
        span_ns = int(cfg.duration_s * NS_PER_S)
        n = span_ns * clk.period_den // clk.period_num_ns
        k = np.arange(n, dtype=np.int64)
        t0_sensor = cfg.start_time_ns + cfg.clock_offset_ns
        stamp = (t0_sensor + (clk.period_num_ns * k) // clk.period_den) // NS_PER_US * NS_PER_US
        capture = stamp - cfg.clock_offset_ns
        azimuth_q = np.empty((n, clk.block_offset_ns.size), dtype=np.int64)
        # In slices: the block times and the rotation model's float temporaries stay small
        # on long logs.
        for lo in range(0, n, _PACKETS_PER_SLICE):
            rows = slice(lo, lo + _PACKETS_PER_SLICE)
            block_true = capture[rows, None] + clk.block_offset_ns[None, :]
            t_rel = (block_true - cfg.start_time_ns).astype(np.float64)
            angle = self.rotation.angle_deg(t_rel)
            azimuth_q[rows] = np.rint(angle * clk.azimuth_units_per_deg)
        delivered = self.rng_drop.random(n) >= cfg.packet_drop_fraction
        t1 = cfg.t1.draw_ns(self.rng_t1, n)
        return _Packets(stamp, capture, None, azimuth_q, delivered, t1, capture + t1)

    def _ouster_packets(self) -> _Packets:
        """Ouster packets: each column fires when the encoder reaches its angle (360 deg x
        measurement id / columns), its time from the rotation; packets start at column
        ids divisible by 16; column stamps are the sensor clock in ns (PTP: epoch)."""
        cfg, clk = self.cfg, self.clock
        cols = clk.azimuth_units_per_deg
        per = ouster_packets.COLUMNS_PER_PACKET
        rot = self.rotation
        end_deg = float(rot.angle_deg(np.array([cfg.duration_s * NS_PER_S]))[0])
        start_deg = float(rot.angle_deg(np.array([0.0]))[0])
        first = math.ceil(start_deg * cols / 360.0 / per) * per
        last = math.floor(end_deg * cols / 360.0 / per) * per
        column = np.arange(first, last, dtype=np.int64).reshape(-1, per)
        t_rel = rot.time_at_ns(column.astype(np.float64) * 360.0 / cols)
        block_true = cfg.start_time_ns + np.rint(t_rel).astype(np.int64)
        capture = block_true[:, 0].copy()
        n = capture.size
        delivered = self.rng_drop.random(n) >= cfg.packet_drop_fraction
        t1 = cfg.t1.draw_ns(self.rng_t1, n)
        return _Packets(
            capture + cfg.clock_offset_ns, capture, block_true, column * 360, delivered, t1,
            capture + t1,
        )  # fmt: skip

    def crossings(self, pk: _Packets) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Zero crossings seen in the delivered packets: (turn numbers m, zero packet index).

        The zero-crossing angle of turn m is zero + 360 m (unwrapped); its packet is the
        first delivered packet holding a block at or past it, with a delivered block before.
        """
        units = self.clock.azimuth_units_per_deg
        full = 360 * units
        idx_delivered = np.flatnonzero(pk.delivered)
        q = pk.azimuth_q[idx_delivered].reshape(-1)
        zero_q = self.zero_deg * units
        m_lo = math.floor((int(q[0]) - zero_q) / full) + 1
        m_hi = math.floor((int(q[-1]) - zero_q) / full)
        turns = np.arange(m_lo, m_hi + 1, dtype=np.int64)
        at = np.searchsorted(q, zero_q + full * turns.astype(np.float64), side="left")
        n_blocks = pk.azimuth_q.shape[1]
        return turns, idx_delivered[at // n_blocks]

    def trigger_packets(
        self, pk: _Packets, zero_packet: NDArray[np.int64], zero_angles: NDArray[np.float64]
    ) -> NDArray[np.int64]:
        """Index of the packet each revolution's triggers fire from (the configured convention).

        Only delivered packets count: the LiDAR driver never saw a lost one. Raises
        ValueError when an offset reaches before the first or past the last packet.
        """
        cfg = self.cfg
        delivered = np.flatnonzero(pk.delivered)
        pos = np.searchsorted(delivered, zero_packet)
        if cfg.trigger_packet == "first_after":
            zero_q = self.zero_deg * self.clock.azimuth_units_per_deg + (
                360 * self.clock.azimuth_units_per_deg
            ) * np.rint((zero_angles - self.zero_deg) / 360.0)
            # The containing packet qualifies when its first block is at or past zero;
            # otherwise the next delivered one does (its first block is past zero).
            first_block = pk.azimuth_q[delivered[pos], 0]
            pos = pos + (first_block < zero_q).astype(np.int64)
        pos = pos + cfg.trigger_packet_offset
        if pos.size and (int(pos.min()) < 0 or int(pos.max()) >= delivered.size):
            raise ValueError(
                f"trigger_packet_offset {cfg.trigger_packet_offset} reaches outside the "
                "simulated packets; lengthen the log or move start_azimuth_deg"
            )
        return delivered[pos]

    # -- cameras --------------------------------------------------------------------------

    def run(self, out: Path) -> dict[str, Any]:
        """Simulate, write the log to `out` and return the truth."""
        cfg = self.cfg
        pk = self.packets()
        turns, zero_packet = self.crossings(pk)
        if turns.size < 3:
            raise ValueError("duration too short: fewer than three zero crossings")
        last_packet = int(zero_packet[-1])
        rot = self.rotation
        zero_angles = self.zero_deg + 360.0 * turns.astype(np.float64)
        zero_true_ns = cfg.start_time_ns + np.rint(rot.time_at_ns(zero_angles)).astype(np.int64)
        # The log holds whole revolutions: it ends with the last zero-crossing packet, and
        # frames belong to revolutions that start and end inside it.
        revs_ns = np.diff(zero_true_ns).astype(np.float64)
        omega_mean_deg_ns = 360.0 * (turns.size - 1) / float(zero_true_ns[-1] - zero_true_ns[0])

        cams = [
            self._camera(i, pk, zero_packet, zero_angles, zero_true_ns, revs_ns, omega_mean_deg_ns)
            for i in range(len(cfg.cameras))
        ]
        written = int(pk.delivered[: last_packet + 1].sum())
        dropped = int((~pk.delivered[: last_packet + 1]).sum())
        written_idx = np.flatnonzero(pk.delivered[: last_packet + 1])
        lidar_truth = {
            "topic": self.topic,
            "msgtype": self.msgtype,
            "vendor": self.vendor,
            "model": cfg.lidar_model,
            "frame_id": cfg.lidar_frame,
            "rpm_nominal": cfg.rpm,
            "rpm_mean": omega_mean_deg_ns * NS_PER_S / 6.0,
            "omega_mean_deg_s": omega_mean_deg_ns * NS_PER_S,
            "rpm_drift_frac": cfg.rpm_drift_frac,
            "rpm_drift_period_s": cfg.rpm_drift_period_s,
            "zero_azimuth_deg": self.zero_deg,
            "azimuth_increases": True,
            "rotation": "clockwise seen from above (packet azimuth grows with time)",
            "azimuth_of_x_axis_deg": self.x_axis_deg,
            "azimuth_resolution_deg": 1.0 / self.clock.azimuth_units_per_deg,
            "clock_offset_ns": cfg.clock_offset_ns,
            "packet_period_ns": self.clock.period_num_ns / self.clock.period_den,
            "packets_written": written,
            "packets_dropped": dropped,
            "revolutions": int(turns.size),
            "scans": int(turns.size),
            "cloud_topic": CLOUD_TOPIC if cfg.cloud_convention is not None else None,
            "cloud_convention": cfg.cloud_convention,
            "zero_crossing_ns": [int(v) for v in zero_true_ns],
            "zero_packet_ns": [int(v) for v in pk.capture_ns[zero_packet]],
            "t1_mean_ns": float(pk.t1_ns[written_idx].mean()),
            "t1_min_ns": int(pk.t1_ns[written_idx].min()),
            "first_packet_ns": int(pk.capture_ns[written_idx[0]]),
            "last_packet_ns": int(pk.capture_ns[written_idx[-1]]),
        }
        truth: dict[str, Any] = {
            "seed": cfg.seed,
            # `controller` is the last key, as when it was a field of the config.
            "config": {
                **cfg.model_dump(mode="json"),
                "controller": None if self.delays is None else self.delays.settings,
            },
            "log": {"path": str(out), "format": cfg.log_format},
            "conventions": {
                "times": "integer ns, true (host) clock; sensor clock = host + clock_offset_ns",
                "t_l": "exposure_start_ns + exposure_duration_ns / 2 (durations are even)",
                "error_ns": "t_l_ns - t_estimated_ns (signed); Eq. 4 t_error = |error_ns|",
                "ideal_delay_ns": "t_estimated - (lidar_packet + t1 + t2 + t3 + t4 + t5/2)",
                "error_var_ns2": "Eq. 6 over all frames of the camera: "
                "(sum(|e|^2)/N - mean(|e|)^2) * N/(N-1)",
                "flir_exposure_time": "ImageMetaData.exposure_time is t5 rounded to the "
                "nearest microsecond (the message holds whole us)",
                "camera_exposure_duration": "CameraExposure.exposure_duration = t5 / 1e9 s "
                "(exact to the ns after rounding)",
                "trigger_stamp": "stamp semantics 'trigger': header.stamp = camera_sensor_time "
                "(246, the trigger reaching the camera)",
                "azimuth": "packets hold azimuths rounded to 0.01 deg; t_estimated is from "
                "the exact azimuth model, so interpolating packets differs by ~1 us",
                "packet_phase_ns": "zero_crossing_ns - lidar_packet_ns: when the beam "
                "crossed the zero azimuth, relative to the trigger packet's capture",
                "t_rotate_ns": "per frame: t_estimated_ns - zero_crossing_ns",
                "trigger_packet": f"{cfg.trigger_packet} packet "
                f"{cfg.trigger_packet_offset:+d} delivered packets: the packet the trigger "
                "fires from and names in lidar_packet_time",
            },
            "lidar": lidar_truth,
            "extra_lidars": [],
            "cameras": {c["name"]: c for c in cams},
        }
        extras = [self._extra(i, extra) for i, extra in enumerate(cfg.extra_lidars)]
        truth["extra_lidars"] = [facts for _, facts in extras]
        self._write(out, pk, zero_packet, cams, [stream for stream, _ in extras])
        return truth

    def _extra(
        self, index: int, extra: ExtraLidarSim
    ) -> tuple[tuple[_Simulation, _Packets, NDArray[np.int64]], dict[str, Any]]:
        """An extra LiDAR's simulation (its own seed, rotation and packet clock), its
        packets and zero packets, and its truth."""
        cfg = self.cfg.model_copy(
            update={
                "seed": self.cfg.seed * 7919 + index + 1,
                "lidar_model": extra.model,
                "rpm": extra.rpm,
                "start_azimuth_deg": extra.start_azimuth_deg,
                "lidar_frame": extra.frame_id,
                "zero_azimuth_deg": None,
                "cloud_convention": None,
                "trigger_design": None,
                "extra_lidars": [],
            }
        )
        sim = _Simulation(cfg, self.outputs, None)
        sim.topic = extra.topic
        pk = sim.packets()
        _, zero_packet = sim.crossings(pk)
        last = int(zero_packet[-1])
        facts = {
            "topic": extra.topic,
            "msgtype": sim.msgtype,
            "model": extra.model,
            "frame_id": extra.frame_id,
            "rpm_nominal": extra.rpm,
            "packets_written": int(pk.delivered[: last + 1].sum()),
            "scans": int(zero_packet.size),
        }
        return (sim, pk, zero_packet), facts

    def _camera(
        self,
        index: int,
        pk: _Packets,
        zero_packet: NDArray[np.int64],
        zero_angles: NDArray[np.float64],
        zero_true_ns: NDArray[np.int64],
        revs_ns: NDArray[np.float64],
        omega_mean_deg_ns: float,
    ) -> dict[str, Any]:
        """Per-frame truth of one camera (one frame per whole revolution).

        In four steps: the trigger chain up to the delay, the applied delays, the times
        they lead to, and the camera's truth record. The camera's random draws happen in
        that order (t2, t3, t4, t5, then the image latency and the image pattern's seed).
        """
        cfg = self.cfg
        rng = np.random.default_rng(self.camera_seeds.spawn(len(cfg.cameras))[index])
        chain = self._chain(index, rng, pk, zero_packet, zero_angles)
        delay_error_ns = round(cfg.cameras[index].delay_error_us * NS_PER_US)
        initial = max(0, round(float(chain.ideal.mean())) + delay_error_ns)
        applied, adjustments = self._applied_delays(chain, initial, revs_ns)
        times = _frame_times(chain, applied, cfg.cameras[index].stamp_semantics)
        design = self._design(index, chain, zero_angles, delay_error_ns, rng)
        if design is not None:
            times = _design_frame_times(chain, design, cfg.cameras[index].stamp_semantics)
        latency = cfg.image_latency.draw_ns(rng, chain.n)
        image_log = times.exposure_start + chain.t5 + latency
        pattern_seed = int(rng.integers(0, 2**31))
        record = self._camera_truth(
            index, chain, times, zero_true_ns[: chain.n], image_log, omega_mean_deg_ns
        )
        record["applied_delay"] = {
            "mode": _delay_mode(self.delays),
            "delay_error_ns": delay_error_ns,
            "initial_ns": int(applied[0]),
            "final_ns": int(applied[-1]),
            "mean_ns": float(applied.mean()),
            "min_ns": int(applied.min()),
            "max_ns": int(applied.max()),
            "adjustments": adjustments,
        }
        record["frames"] = _rows(
            {
                "frame_sequence": np.arange(chain.n),
                "lidar_packet_ns": chain.packet_ns,
                "t1_ns": chain.t1,
                "t2_ns": chain.t2,
                "t3_ns": chain.t3,
                "t4_ns": chain.t4,
                "applied_delay_ns": applied,
                "exposure_start_ns": times.exposure_start,
                "exposure_duration_ns": chain.t5,
                "t_l_ns": times.t_l,
                "t_estimated_ns": chain.t_est,
                "error_ns": times.error,
                "ideal_delay_ns": chain.ideal,
                "zero_crossing_ns": zero_true_ns[: chain.n],
                "packet_phase_ns": zero_true_ns[: chain.n] - chain.packet_ns,
                "t_rotate_ns": chain.t_est - zero_true_ns[: chain.n],
                "image_stamp_ns": times.stamp,
                "image_log_time_ns": image_log,
            }
        )
        if design is not None:
            record["trigger_design"] = _design_truth(self.cfg, index, design, times)
            if design.trigger_ns is not None:
                for row, trigger in zip(record["frames"], design.trigger_ns.tolist(), strict=True):
                    row["trigger_ns"] = trigger
        record["_arrays"] = {
            "exposure_ratio": chain.exposure_ratio,
            "pattern_seed": pattern_seed,
            "image_stamp": times.stamp,
            "image_log": image_log,
        }
        return record

    def _chain(
        self,
        index: int,
        rng: np.random.Generator,
        pk: _Packets,
        zero_packet: NDArray[np.int64],
        zero_angles: NDArray[np.float64],
    ) -> _Chain:
        """Step 1: when each frame should be exposed, and the chain's latencies to it."""
        cfg = self.cfg
        n = int(zero_packet.size) - 1
        theta = (self.camera_azimuth_deg[index] - self.zero_deg) % 360.0
        t_est_rel = self.rotation.time_at_ns(zero_angles[:n] + theta)
        t_est = cfg.start_time_ns + np.rint(t_est_rel).astype(np.int64)
        trigger = self.trigger_packets(pk, zero_packet[:n], zero_angles[:n])
        packet_ns = pk.capture_ns[trigger]
        t1 = pk.t1_ns[trigger]
        t2 = cfg.t2.draw_ns(rng, n)
        t3 = cfg.t3.draw_ns(rng, n)
        t4 = cfg.t4.draw_ns(rng, n)
        t5, exposure_ratio = _exposures_ns(cfg.light, t_est_rel / NS_PER_S, cfg.duration_s, rng)
        ideal = t_est - (packet_ns + t1 + t2 + t3 + t4 + t5 // 2)
        return _Chain(n, theta, t_est, packet_ns, t1, t2, t3, t4, t5, exposure_ratio, ideal)

    def _design(
        self,
        index: int,
        chain: _Chain,
        zero_angles: NDArray[np.float64],
        delay_error_ns: int,
        rng: np.random.Generator,
    ) -> DesignTimes | None:
        """The camera's frames under `trigger_design` (None: the chain triggers them)."""
        design = self.cfg.trigger_design
        if design is None:
            return None
        pulse_deg = (
            design.sync_output_angle_deg
            if design.sync_output_angle_deg is not None
            else self.zero_deg
        )

        def pulse() -> NDArray[np.int64]:
            angle = zero_angles[: chain.n] + (pulse_deg - self.zero_deg) % 360.0
            rel = self.rotation.time_at_ns(angle)
            return self.cfg.start_time_ns + np.rint(rel).astype(np.int64)

        return design_times(
            design,
            self.cfg.cameras[index].name,
            t_est_ns=chain.t_est,
            t4_ns=chain.t4,
            t5_ns=chain.t5,
            pulse_true_ns=pulse,
            delay_error_ns=delay_error_ns,
            rng=rng,
        )

    def _applied_delays(
        self, chain: _Chain, initial_ns: int, revs_ns: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], list[dict[str, Any]]]:
        """Step 2: the delay each frame is triggered with, and the changes made to it."""
        if self.delays is None:
            return np.full(chain.n, initial_ns, dtype=np.int64), []
        if isinstance(self.delays, CompensatedDelays):
            return self.delays.applied_ns(initial_ns, chain.t5), []
        return self._live_delays(self.delays.for_camera(initial_ns), initial_ns, chain, revs_ns)

    def _camera_truth(
        self,
        index: int,
        chain: _Chain,
        times: _FrameTimes,
        zero_ns: NDArray[np.int64],
        image_log: NDArray[np.int64],
        omega_mean_deg_ns: float,
    ) -> dict[str, Any]:
        """Step 4: the camera's summary in the truth (its frames are added by the caller)."""
        cam = self.cfg.cameras[index]
        err_mean, err_var = _eq5_eq6(np.abs(times.error))
        ideal_mean = float(chain.ideal.mean())
        return {
            "name": cam.name,
            "frame_id": f"{cam.name}_optical_frame",
            "yaw_deg": cam.yaw_deg,
            "azimuth_deg": self.camera_azimuth_deg[index],
            "theta_deg": chain.theta_deg,
            "hfov_deg": cam.hfov_deg,
            "stamp_semantics": cam.stamp_semantics,
            "topics": self._camera_topics(cam),
            "frames_count": chain.n,
            "t_rotate_ns": round(chain.theta_deg / omega_mean_deg_ns),
            "t1_mean_ns": float(chain.t1.mean()),
            "t2_mean_ns": float(chain.t2.mean()),
            "t3_mean_ns": float(chain.t3.mean()),
            "t4_mean_ns": float(chain.t4.mean()),
            "t5_mean_ns": float(chain.t5.mean()),
            "t5_window_frames": (
                self.delays.window_frames if self.delays is not None else CONSTANT_WINDOW_FRAMES
            ),
            "packet_phase_mean_ns": float((zero_ns - chain.packet_ns).mean()),
            "error_signed_mean_ns": float(times.error.mean()),
            "error_mean_ns": err_mean,
            "error_var_ns2": err_var,
            "ideal_delay_ns": round(ideal_mean),
            "ideal_delay_mean_ns": ideal_mean,
        }

    def _camera_topics(self, cam: CameraSim) -> dict[str, str]:
        """The topics one camera's messages go to, by kind (shared ones: `SHARED_TOPICS`)."""
        cfg = self.cfg
        prefix = f"/cameras/{cam.name}"
        topics: dict[str, str] = {"image": f"{prefix}/image_raw"}
        if "camera_exposure" in cfg.exposure_messages:
            topics["exposure"] = f"{prefix}/exposure"
        if "flir_meta" in cfg.exposure_messages:
            topics["meta"] = f"{prefix}/meta"
        free_running = (
            cfg.trigger_design is not None and cfg.trigger_design.design == "free_running"
        )
        if cfg.trigger_messages and not free_running:
            topics["trigger"] = f"{prefix}/trigger"
        for kind in topics:
            if kind in cfg.shared_topics:
                topics[kind] = SHARED_TOPICS[kind]
        if cfg.image_kind != "raw":
            topics["image"] += "/compressed"
        return topics

    def _live_delays(
        self,
        policy: CameraDelays,
        initial_ns: int,
        chain: _Chain,
        revs_ns: NDArray[np.float64],
    ) -> tuple[NDArray[np.int64], list[dict[str, Any]]]:
        """Run a caller's policy live: frame i uses the delay decided after frame i - 1.

        t_rotate of frame i is theta over the previous revolution's measured rate (the
        nominal rate for the first frame); the error is the frame's true signed error.
        """
        applied = np.empty(chain.n, dtype=np.int64)
        adjustments: list[dict[str, Any]] = []
        delay = initial_ns
        w0 = self.rotation.w0_deg_ns
        lists = [a.tolist() for a in (chain.t1, chain.t2, chain.t3, chain.t4, chain.t5)]
        ideal = chain.ideal.tolist()
        for i in range(chain.n):
            applied[i] = delay
            omega = w0 if i == 0 else 360.0 / float(revs_ns[i - 1])
            frame = FrameTiming(
                t1_ns=lists[0][i],
                t2_ns=lists[1][i],
                t3_ns=lists[2][i],
                t4_ns=lists[3][i],
                exposure_ns=lists[4][i],
                error_ns=delay - ideal[i],
                t_rotate_ns=round(chain.theta_deg / omega),
            )
            delay, changes = policy.update(frame)
            adjustments.extend(asdict(change) for change in changes)
        return applied, adjustments

    # -- writing --------------------------------------------------------------------------

    def _scan_messages(
        self, writer: LogWriter, pk: _Packets, zero_packet: NDArray[np.int64]
    ) -> Iterator[tuple[int, int, str, bytes | Callable[[], bytes]]]:
        """One scan per zero crossing: delivered packets after the previous zero packet up
        to and including this one; header stamp and log time = last packet's driver stamp."""
        if self.vendor == "ouster":
            yield from self._ouster_messages(writer, pk, zero_packet)
            return
        units = self.clock.azimuth_units_per_deg
        full = 360 * units
        begin = 0
        for j, zp in enumerate(zero_packet.tolist()):
            rows = np.arange(begin, zp + 1)
            begin = zp + 1
            azimuth_deg = (pk.azimuth_q[rows] % full) / units
            keep = pk.delivered[rows]
            data, size = self._encode(azimuth_deg, pk.stamp_sensor_ns[rows], int(rows[0]))
            stamps = pk.driver_ns[rows][keep]
            log_time = int(pk.driver_ns[zp])
            if self.vendor == "velodyne":
                payload = build_velodyne_scan(
                    log_time, self.cfg.lidar_frame, stamps, data[keep], writer.encoding, seq=j
                )
            else:
                payload = build_pandar_scan(
                    RosHeader(log_time, self.cfg.lidar_frame, j),
                    stamps,
                    data[keep],
                    size[keep],
                    writer.encoding,
                )
            yield (log_time, -1, self.topic, payload)

    def _cloud_messages(
        self, writer: LogWriter, pk: _Packets, zero_packet: NDArray[np.int64]
    ) -> Iterator[tuple[int, int, str, bytes | Callable[[], bytes]]]:
        """The scans of `_scan_messages` as point clouds (cfg.cloud_convention), one per
        scan at the same log time, from the same delivered packets' firing times."""
        convention = self.cfg.cloud_convention
        if convention is None:
            return
        offset_ns, start_ns = self.cfg.clock_offset_ns, self.cfg.start_time_ns
        beams = self.cfg.cloud_beams

        def azimuth_at(sensor_ns: NDArray[np.int64]) -> NDArray[np.float64]:
            t_rel = (sensor_ns - offset_ns - start_ns).astype(np.float64)
            return self.rotation.angle_deg(t_rel) % 360.0

        begin = 0
        for zp in zero_packet.tolist():
            rows = np.arange(begin, zp + 1)
            begin = zp + 1
            rows = rows[pk.delivered[rows]]
            blocks = pk.stamp_sensor_ns[rows][:, None] + self.clock.block_offset_ns[None, :]
            points = cloud_points(blocks.reshape(-1), beams, azimuth_at)
            # Published once its last beam has fired and reached the driver (t1 later).
            log_ns = int(points.time_ns.max()) - offset_ns + int(pk.t1_ns[zp])
            _, msg = cloud_message(
                writer,
                convention,
                points,
                self.cfg.lidar_frame,
                self.x_axis_deg,
                stamp="last" if convention == "velodyne" else "first",
            )
            yield (log_ns, -1, CLOUD_TOPIC, writer.serialize(msg))

    def _ouster_messages(
        self, writer: LogWriter, pk: _Packets, zero_packet: NDArray[np.int64]
    ) -> Iterator[tuple[int, int, str, bytes | Callable[[], bytes]]]:
        """The metadata first, then one PacketMsg per delivered packet up to the last zero
        packet, logged at its driver stamp (as ouster-ros publishes them)."""
        cfg = self.cfg
        cols = self.clock.azimuth_units_per_deg
        text = ouster_packets.metadata_json(cfg.ouster_profile, cfg.rpm)
        meta = writer.serialize(writer.new_msg("std_msgs/msg/String", data=text))
        yield (int(pk.driver_ns[0]) - 1, -2, self.metadata_topic, meta)
        end = int(zero_packet[-1]) + 1
        for lo in range(0, end, 4096):
            rows = np.arange(lo, min(end, lo + 4096))
            column = pk.azimuth_q[rows] // 360
            assert pk.block_true_ns is not None  # Ouster packets keep their column stamps
            stamps = pk.block_true_ns[rows] + cfg.clock_offset_ns
            data = ouster_packets.encode_packets(
                cfg.ouster_profile, column % cols, stamps, column[:, 0] // cols, cols
            )
            for k, p in enumerate(rows.tolist()):
                if pk.delivered[p]:
                    payload = ouster_packets.packet_msg(data[k].tobytes(), writer.encoding)
                    yield (int(pk.driver_ns[p]), -1, self.topic, payload)

    @property
    def metadata_topic(self) -> str:
        """Ouster: the sensor metadata topic beside the packets (ouster-ros' name)."""
        return self.topic.rsplit("/", 1)[0] + "/metadata"

    def _encode(
        self, azimuth_deg: NDArray[np.float64], stamp_ns: NDArray[np.int64], first_index: int
    ) -> tuple[NDArray[np.uint8], NDArray[np.uint32]]:
        """Real-format packets of consecutive sensor packets (delivered or not)."""
        cfg = self.cfg
        n, b = azimuth_deg.shape
        distances: NDArray[np.float64] | None = None
        if cfg.lidar_returns == "smooth":
            channels = (
                32  # records per Velodyne block
                if self.vendor == "velodyne"
                else (HESAI_LAYOUTS[cfg.lidar_model].n_channels)
            )
            rad = np.radians(azimuth_deg)[:, :, None]
            ring = np.arange(channels, dtype=np.float64)[None, None, :]
            distances = 12.0 + 6.0 * np.abs(np.sin(rad)) + 3.0 * np.cos(2.0 * rad) + 0.25 * ring
            distances = np.broadcast_to(distances, (n, b, channels))
        if self.vendor == "velodyne":
            toh_us = (stamp_ns // NS_PER_US) % HOUR_US
            data = encode_velodyne(
                cfg.lidar_model,
                azimuth_deg,
                toh_us,
                RETURN_STRONGEST,
                rng=self.rng_points,
                distances_m=distances,
                intensities=None if distances is None else np.uint8(40),
            )
            return data, np.full(n, data.shape[1], dtype=np.uint32)
        reflectivity = None if distances is None else np.full(distances.shape, 40, np.uint8)
        return encode_hesai(
            cfg.lidar_model,
            azimuth_deg,
            stamp_ns,
            _HESAI_RETURN_MODE.get(cfg.lidar_model, HESAI_RETURN_STRONGEST),
            distance_m=None if distances is None else np.ascontiguousarray(distances),
            reflectivity=reflectivity,
            rng=self.rng_points,
            motor_rpm=round(cfg.rpm),
            udp_sequence_start=1 + first_index,
        )

    def _camera_messages(self, writer: LogWriter, cams: list[dict[str, Any]]) -> _Outgoing:
        """Image, exposure, metadata and trigger messages of every frame, serialized."""
        cfg = self.cfg
        out = _Outgoing([])
        tf_msgs = []
        for cam_cfg, cam in zip(cfg.cameras, cams, strict=True):
            qx, qy, qz, qw = _camera_quaternion(cam_cfg.yaw_deg)
            yaw = math.radians(cam_cfg.yaw_deg)
            transform = writer.new_msg(
                "geometry_msgs/msg/Transform",
                translation=writer.new_msg(
                    "geometry_msgs/msg/Vector3",
                    x=0.12 * math.cos(yaw),
                    y=0.12 * math.sin(yaw),
                    z=-0.2,
                ),
                rotation=writer.new_msg("geometry_msgs/msg/Quaternion", x=qx, y=qy, z=qz, w=qw),
            )
            tf_msgs.append(
                writer.new_msg(
                    "geometry_msgs/msg/TransformStamped",
                    header=writer.header(cfg.start_time_ns, cfg.lidar_frame),
                    child_frame_id=cam["frame_id"],
                    transform=transform,
                )
            )
        out.add(
            cfg.start_time_ns,
            "/tf_static",
            writer.serialize(writer.new_msg("tf2_msgs/msg/TFMessage", transforms=tf_msgs)),
        )
        shared_seq = _shared_topic_seqs(cams)
        for index, (cam_cfg, cam) in enumerate(zip(cfg.cameras, cams, strict=True)):
            self._frames_of(writer, cam_cfg, cam, out, shared_seq[index])
        return out

    def _frames_of(
        self,
        writer: LogWriter,
        cam_cfg: CameraSim,
        cam: dict[str, Any],
        out: _Outgoing,
        shared_seq: NDArray[np.int64],
    ) -> None:
        cfg = self.cfg
        arrays = cam["_arrays"]
        topics = cam["topics"]
        frame_id = cam["frame_id"] if cfg.header_frame_ids else ""
        camera_name = cam["name"] if cfg.camera_field else ""
        pattern_rng = np.random.default_rng(arrays["pattern_seed"])
        height, width = 24, 32
        gradient = np.linspace(0.6, 1.4, width)[None, :] * np.linspace(1.2, 0.8, height)[:, None]
        ros1 = writer.encoding == "ros1"

        def hdr(stamp_ns: int, i: int, kind: str) -> Any:
            """Header of this camera's frame i on its `kind` topic; ROS 1 publishers number
            their messages in `seq` (per topic: a shared topic counts every camera's)."""
            fields: dict[str, Any] = {"stamp": writer.time(stamp_ns), "frame_id": frame_id}
            if ros1:
                seq = int(shared_seq[i]) if kind in cfg.shared_topics else i
                fields["seq"] = seq if cfg.ros1_header_seq else 0
            return writer.new_msg("std_msgs/msg/Header", **fields)

        for i, frame in enumerate(cam["frames"]):
            stamp_ns = int(arrays["image_stamp"][i])
            log_ns = int(arrays["image_log"][i])
            seq = frame["frame_sequence"]
            header = hdr(stamp_ns, i, "image")
            level = 110.0 * float(arrays["exposure_ratio"][i])
            noise = pattern_rng.normal(0.0, 2.0, (height, width))
            pixels = np.clip(level * gradient + noise, 0, 255).astype(np.uint8)
            image: bytes | Callable[[], bytes]
            if cfg.image_bytes is not None:
                jpeg_seed = int(pattern_rng.integers(0, 2**63))
                image = partial(_jpeg_image, writer, header, cfg.image_bytes, jpeg_seed)
            elif cfg.image_kind == "raw":
                image = writer.serialize(
                    writer.new_msg(
                        "sensor_msgs/msg/Image",
                        header=header,
                        height=height,
                        width=width,
                        encoding="mono8",
                        step=width,
                        data=pixels.reshape(-1),
                    )
                )
            else:
                image = writer.serialize(
                    writer.new_msg(
                        "sensor_msgs/msg/CompressedImage",
                        header=header,
                        format="mono8; png compressed",
                        data=np.frombuffer(_png_gray(pixels), dtype=np.uint8),
                    )
                )
            out.add(log_ns, topics["image"], image)
            t5 = frame["exposure_duration_ns"]
            if "exposure" in topics:
                msg = writer.new_msg(
                    "syncaudit_msgs/msg/CameraExposure",
                    header=hdr(frame["exposure_start_ns"], i, "exposure"),
                    camera=camera_name,
                    frame_sequence=seq,
                    exposure_start=writer.time(frame["exposure_start_ns"]),
                    exposure_duration=t5 / NS_PER_S,
                    gain_db=0.0,
                )
                out.add(log_ns + 1_000, topics["exposure"], writer.serialize(msg))
            if "meta" in topics:
                msg = writer.new_msg(
                    "flir_camera_msgs/msg/ImageMetaData",
                    header=hdr(stamp_ns, i, "meta"),
                    camera_time=frame["exposure_start_ns"] - cfg.start_time_ns + 3_600 * NS_PER_S,
                    brightness=int(pixels.mean()),
                    exposure_time=round(t5 / NS_PER_US),
                    max_exposure_time=FLIR_MAX_EXPOSURE_US,
                    gain=0.0,
                )
                out.add(log_ns + 2_000, topics["meta"], writer.serialize(msg))
            if "trigger" in topics:
                packet = frame["lidar_packet_ns"]
                driver = packet + frame["t1_ns"]
                cam_driver = driver + frame["t2_ns"]
                cam_sensor = cam_driver + frame["applied_delay_ns"] + frame["t3_ns"]
                if "trigger_ns" in frame:  # a trigger design: the bare trigger time (host)
                    msg = writer.time(frame["trigger_ns"])
                elif cfg.trigger_message == "time_reference":
                    msg = writer.new_msg(
                        "sensor_msgs/msg/TimeReference",
                        header=hdr(cam_sensor, i, "trigger"),
                        time_ref=writer.time(cam_sensor),
                        source="",
                    )
                else:
                    msg = writer.new_msg(
                        "syncaudit_msgs/msg/TriggerEvent",
                        header=hdr(cam_sensor, i, "trigger"),
                        camera=camera_name,
                        frame_sequence=seq,
                        lidar_packet_time=writer.time(packet),
                        lidar_driver_time=writer.time(driver),
                        camera_driver_time=writer.time(cam_driver),
                        camera_sensor_time=writer.time(cam_sensor),
                        exposure_start_time=writer.time(frame["exposure_start_ns"]),
                        applied_delay=frame["applied_delay_ns"] / NS_PER_S,
                    )
                out.add(log_ns + 3_000, topics["trigger"], writer.serialize(msg))

    def _write(
        self,
        out: Path,
        pk: _Packets,
        zero_packet: NDArray[np.int64],
        cams: list[dict[str, Any]],
        extras: list[tuple[_Simulation, _Packets, NDArray[np.int64]]],
    ) -> None:
        cfg = self.cfg
        with open_writer(
            out,
            cfg.log_format,
            overwrite=cfg.overwrite,
            outputs=self.outputs,
            bag_compression=cfg.bag_compression,
        ) as writer:
            writer.add_topic("/tf_static", "tf2_msgs/msg/TFMessage", latched=True)
            if cfg.lidar_packets:
                writer.add_topic(self.topic, self.msgtype)
                if self.vendor == "ouster":
                    writer.add_topic(self.metadata_topic, "std_msgs/msg/String")
            for sim, _, _ in extras:
                writer.add_topic(sim.topic, sim.msgtype)
            if cfg.cloud_convention is not None:
                writer.add_topic(CLOUD_TOPIC, "sensor_msgs/msg/PointCloud2")
            image_type = (
                "sensor_msgs/msg/Image"
                if cfg.image_kind == "raw"
                else "sensor_msgs/msg/CompressedImage"
            )
            types = {
                "image": image_type,
                "exposure": "syncaudit_msgs/msg/CameraExposure",
                "meta": "flir_camera_msgs/msg/ImageMetaData",
                "trigger": "builtin_interfaces/msg/Time"
                if cfg.trigger_design is not None
                else "sensor_msgs/msg/TimeReference"
                if cfg.trigger_message == "time_reference"
                else "syncaudit_msgs/msg/TriggerEvent",
            }
            declared: set[str] = set()
            for cam in cams:
                for kind, topic in cam["topics"].items():
                    if topic not in declared:  # a shared topic is declared once
                        writer.add_topic(topic, types[kind])
                        declared.add(topic)
            camera_msgs = self._camera_messages(writer, cams)
            camera_msgs.items.sort()
            merged = heapq.merge(
                self._scan_messages(writer, pk, zero_packet) if cfg.lidar_packets else iter(()),
                self._cloud_messages(writer, pk, zero_packet),
                *(sim._scan_messages(writer, xpk, xzero) for sim, xpk, xzero in extras),
                iter(camera_msgs.items),
                key=lambda item: (item[0], item[1]),
            )
            for log_time, _order, topic, data in merged:
                writer.write(topic, log_time, data() if callable(data) else data)


def _shared_topic_seqs(cams: list[dict[str, Any]]) -> list[NDArray[np.int64]]:
    """Per camera, the ROS 1 header seq of each frame's message on a shared topic.

    One publisher numbers the messages of its topic in the order it publishes them: the
    frames of every camera by image log time (ties by camera order); every shared kind
    is written in that same order (exposure, metadata and trigger follow their image).
    """
    log_ns = np.concatenate([np.asarray(c["_arrays"]["image_log"], np.int64) for c in cams])
    camera = np.concatenate([np.full(len(c["frames"]), k) for k, c in enumerate(cams)])
    order = np.lexsort((camera, log_ns))
    rank = np.empty(order.size, dtype=np.int64)
    rank[order] = np.arange(order.size)
    bounds = np.cumsum([0, *(len(c["frames"]) for c in cams)])
    return [rank[bounds[k] : bounds[k + 1]] for k in range(len(cams))]


def _jpeg_image(writer: LogWriter, header: Any, size: int, seed: int) -> bytes:
    """A serialized CompressedImage with a JPEG-like payload of `size` bytes."""
    data = np.frombuffer(_jpeg_like(size, seed), dtype=np.uint8)
    msg = writer.new_msg(
        "sensor_msgs/msg/CompressedImage", header=header, format=JPEG_FORMAT, data=data
    )
    return writer.serialize(msg)


def _delay_mode(delays: LiveDelays | CompensatedDelays | None) -> str:
    """The truth's `applied_delay.mode`: 'constant', 'compensated' or 'controller'."""
    if delays is None:
        return "constant"
    return "compensated" if isinstance(delays, CompensatedDelays) else "controller"


def simulate_sync_log(
    out: Path,
    config: SyncSimConfig,
    *,
    outputs: OutputSet | None = None,
    delays: LiveDelays | CompensatedDelays | None = None,
) -> dict[str, Any]:
    """Write a simulated log to `out` (format `config.log_format`) and its truth to `<out>.truth.json`.

    Returns the truth. `delays` runs live on every camera (a delay controller the caller
    supplies, see `syncaudit.simulate.delays`); `CompensatedDelays` compensates each frame's
    own exposure exactly; None keeps each camera's delay constant. Both outputs go through `outputs` (committed by its owner) or, without
    one, through an own OutputSet committed here: all or nothing.

    Raises:
        OutputError: an output exists without `config.overwrite`, or cannot be written.
    """
    out = Path(out)
    own = outputs is None
    outputs = (
        outputs
        if outputs is not None
        else OutputSet(
            overwrite=config.overwrite, overwrite_hint="set overwrite=True to replace it"
        )
    )
    try:
        truth_file = truth_path(out)
        outputs.add(truth_file)
        sim = _Simulation(config, outputs, delays)
        truth = sim.run(out)
        for cam in truth["cameras"].values():
            cam.pop("_arrays")
        outputs.write_text(
            truth_file, json.dumps(marked_json(truth), indent=1, allow_nan=True) + "\n"
        )
    except BaseException:
        if own:
            outputs.discard()
        raise
    if own:
        outputs.commit()
    return truth


_LIDAR_ALIASES: dict[str, LidarModel] = {
    alias: model
    for model in typing.get_args(LidarModel)
    for alias in (
        model.lower(),
        model.lower().replace("-", ""),
        model.lower().removeprefix("pandar"),
    )
}
_LIDAR_ALIASES["ouster"] = "OS-1-64"


def lidar_model(name: str) -> LidarModel:
    """The simulator's LiDAR model for a name as users write it (`XT32`, `vlp16`, `Pandar40P`).

    Raises:
        ConfigError: the name is none of the simulated models.
    """
    found = _LIDAR_ALIASES.get(name.strip().lower().replace("_", "-")) or _LIDAR_ALIASES.get(
        name.strip().lower().replace("-", "").replace("_", "")
    )
    if found is None:
        known = ", ".join(typing.get_args(LidarModel))
        raise ConfigError(f"unknown LiDAR model {name!r}; the simulator writes {known}")
    return found


def sync_sim_config(
    base: Mapping[str, Any] | None = None,
    *,
    lidar: str | None = None,
    tunnel: bool | None = None,
    delay_error_us: float | None = None,
    clock_offset_s: float | None = None,
    compressed: bool | None = None,
    stamp: str | None = None,
    **settings: Any,
) -> SyncSimConfig:
    """A SyncSimConfig from `base` (SyncSimConfig fields, as a config file holds them), the
    `settings` over it, and the shorthands `syncaudit simulate sync` offers over both.

    The shorthands (None: as `base` has it): `lidar` the names users write (`XT32`,
    `vlp-16`); `tunnel=False` keeps the exposure bright all along; `delay_error_us` offsets
    every camera's applied delay from the ideal; `clock_offset_s` is the LiDAR clock minus
    the host clock; `compressed` picks CompressedImage; `stamp` what every camera's image
    header stamp marks. Every other keyword is a SyncSimConfig field (`seed`, `duration_s`,
    `log_format`, `packet_drop_fraction`, `shared_topics`, ...). Defaults are the model's.

    Raises:
        ConfigError: naming the first setting out of range.
    """
    data: dict[str, Any] = {**(base or {}), **settings}
    if lidar is not None:
        data["lidar_model"] = lidar_model(lidar)
    if clock_offset_s is not None:
        data["clock_offset_ns"] = round(clock_offset_s * 1e9)
    if tunnel is False:
        light = _plain(data.get("light", LightModel()))
        if not isinstance(light, Mapping):
            raise ConfigError("light: must be a mapping of LightModel settings")
        bright = light.get(
            "bright_exposure_us", LightModel.model_fields["bright_exposure_us"].default
        )
        data["light"] = {**light, "dark_exposure_us": bright}
    if compressed is not None:
        data["image_kind"] = "compressed" if compressed else "raw"
    camera_updates: dict[str, Any] = {}
    if delay_error_us is not None:
        camera_updates["delay_error_us"] = delay_error_us
    if stamp is not None:
        camera_updates["stamp_semantics"] = stamp
    if camera_updates:
        cameras = data.get("cameras", _default_cameras())
        plain = [_plain(camera) for camera in cameras] if isinstance(cameras, list) else None
        if plain is None or not all(isinstance(camera, Mapping) for camera in plain):
            raise ConfigError("cameras: must be a list of camera mappings")
        # As mappings, so that the settings are validated.
        data["cameras"] = [{**camera, **camera_updates} for camera in plain]
    return SyncSimConfig.model_validate(data)


def _plain(value: Any) -> Any:
    """A model as its field mapping (anything else unchanged), to be updated and validated."""
    return value.model_dump() if isinstance(value, ConfigModel) else value
