"""What the audit's one pass reads, and what it makes of each message.

The plan names the rig's LiDAR topic (decoded to packet timing samples by
`lidar.scan.packet_samples_of`) and every camera topic (rows by
`camera.frame_rows.CameraRowExtractor`), and is the `logs.parallel.Extractor` of the pass:
each message becomes a (kind, topic, payload) item, kind 'lidar', 'image', 'exposure' or
'trigger', in worker processes where the log allows.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from syncaudit.audit.probe import LogProbe, probe_of
from syncaudit.camera.azimuth import x_axis_azimuth_deg
from syncaudit.camera.extract import CameraTableBuilder
from syncaudit.camera.frame_rows import CameraRowExtractor
from syncaudit.camera.routing import CameraRouter
from syncaudit.errors import NoDataError
from syncaudit.lidar import ouster
from syncaudit.lidar.cloud_samples import CloudSettings, cloud_samples
from syncaudit.lidar.cloud_scan import is_cloud_type
from syncaudit.lidar.scan import packet_samples_of
from syncaudit.lidar.stream import find_ouster_metadata_topic
from syncaudit.logs import LogReader, RawMessage
from syncaudit.rig import CameraConfig, Rig

__all__ = ["ExtractPlan", "Item", "read_plan"]

Item = tuple[str, str, Any]
"""(kind, topic, payload): kind is 'lidar', 'image', 'exposure', 'trigger'."""


@dataclass(frozen=True, slots=True)
class ExtractPlan:
    """Which topics the audit reads and what to make of each; picklable for workers."""

    lidar_topic: str
    lidar_family: str
    ouster_meta: ouster.OusterMetadata | None
    cameras: CameraRowExtractor
    cloud: CloudSettings | None = None
    """Set where the LiDAR topic is PointCloud2: how to read its timing."""
    lidar_model: str | None = None
    """The rig's `lidar.model` (Velodyne), else None: the packets tell."""

    @property
    def topics(self) -> list[str]:
        """Every topic the plan reads."""
        return sorted({self.lidar_topic, *self.cameras.topics})

    def prefix_bytes(self, topic: str) -> int:
        """Of an image, its header only (`camera.frame_rows.IMAGE_PREFIX_BYTES`)."""
        return self.cameras.prefix_bytes(topic)

    def rosbags_encodings(self, log: LogReader) -> set[str]:
        """Encodings of the camera messages read through rosbags (packets never are)."""
        return self.cameras.rosbags_encodings(log)

    def extract(self, msg: RawMessage, log: LogReader) -> Item | None:
        """The item one message contributes (None for nothing, e.g. an IMU-sized packet)."""
        if msg.topic == self.lidar_topic and self.cloud is not None:
            cloud = cloud_samples(msg, self.cloud)
            return None if cloud is None else ("lidar", msg.topic, cloud)
        if msg.topic == self.lidar_topic:
            samples = packet_samples_of(msg, self.lidar_family, self.ouster_meta, self.lidar_model)
            return None if samples is None else ("lidar", msg.topic, samples)
        return self.cameras.extract(msg, log)


def read_plan(
    log: LogReader | LogProbe, rig: Rig, cameras: list[CameraConfig]
) -> tuple[ExtractPlan, CameraRouter]:
    """What to read, and where each camera topic's rows go (topics may be shared).

    Raises NoDataError where the LiDAR topic is not packets, or Ouster packets have no
    sensor metadata.
    """
    probe = probe_of(log)
    lidar = rig.lidar
    family = probe.family(lidar.topic)
    cloud = None
    if family is None and is_cloud_type(probe.topics[lidar.topic].msgtype):
        family, cloud = "cloud", cloud_settings(rig)
    if family is None:
        raise NoDataError(
            f"{lidar.topic}: {probe.topics[lidar.topic].msgtype} is not a LiDAR packet type"
        )
    meta = None
    if family == "ouster":
        meta_topic = lidar.metadata_topic or find_ouster_metadata_topic(probe.log, lidar.topic)
        if meta_topic is None:
            raise NoDataError(f"{lidar.topic}: Ouster packets need the sensor metadata topic")
        meta = probe.ouster_metadata(meta_topic)
    router = CameraRouter.for_cameras(cameras, probe.topics)
    images = {t: _owner(o) for t, o in router.topics("image").items()}
    exposures: dict[str, tuple[str, str]] = {
        t: (_owner(o), o[0].camera.stamp) for t, o in router.topics("exposure").items()
    }
    triggers = {t: _owner(o) for t, o in router.topics("trigger").items()}
    rows = CameraRowExtractor(images, exposures, triggers)
    return ExtractPlan(lidar.topic, family, meta, rows, cloud, lidar.model), router


def cloud_settings(rig: Rig) -> CloudSettings:
    """How to read the rig's PointCloud2 LiDAR topic: the +X azimuth the cameras use too."""
    lidar = rig.lidar
    x_axis, _ = x_axis_azimuth_deg(lidar, lidar.vendor)
    return CloudSettings(
        x_axis_azimuth_deg=0.0 if x_axis is None else x_axis,
        clockwise=lidar.azimuth_clockwise_from_above,
        time_field=lidar.time_field,
        stamp_marks=lidar.stamp_marks,
        vendor=lidar.vendor or "cloud",
    )


def _owner(owners: list[CameraTableBuilder]) -> str:
    """The camera the plan names for a topic's rows: "" for a shared topic, whose rows the
    router gives to the camera each message names."""
    return owners[0].camera.name if len(owners) == 1 else ""
