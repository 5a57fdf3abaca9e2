"""One look at an opened log before its one pass: what the audit's steps ask of it first.

The rig guess (topic types, the camera topics' first messages), the rig check (the first
Nebula scan, for the vendor), the camera placement (`/tf_static`) and the read plan (the
LiDAR's packet family, Ouster sensor metadata) each need a little of the log before the
pass that reads it whole. A `LogProbe` reads each of those at most once, when first asked
(so the order the log is read in, and what it warns, is each step's own), and hands the
same answer to every step that asks again.
"""

from __future__ import annotations

from syncaudit.camera.azimuth import tf_static_yaws
from syncaudit.camera.camera_topics import CameraProbe, probe_camera_topics, topic_role
from syncaudit.lidar import ouster
from syncaudit.lidar.packet_topics import LidarTopicGuess, guess_lidar_topics
from syncaudit.lidar.stream import SCAN_TYPES, decode_scan, read_ouster_metadata
from syncaudit.logs import LogReader, TopicInfo

__all__ = ["LogProbe", "lidar_family", "probe_of"]


def lidar_family(msgtype: str) -> str | None:
    """The vendor family of a LiDAR packet message type (None: not a packet type)."""
    return SCAN_TYPES.get(msgtype)


class LogProbe:
    """What the audit's steps learn of one open log before reading it, each read once."""

    __slots__ = ("_cameras", "_lidar_guess", "_ouster", "_tf_yaws", "_vendors", "log")

    def __init__(self, log: LogReader) -> None:
        self.log = log
        self._lidar_guess: LidarTopicGuess | None = None
        self._cameras: CameraProbe | None = None
        self._tf_yaws: dict[str, float] | None = None
        self._ouster: dict[str, ouster.OusterMetadata] = {}
        self._vendors: dict[str, str | None] = {}

    @property
    def topics(self) -> dict[str, TopicInfo]:
        """The log's topics (types, encodings, counts)."""
        return self.log.topics

    def lidar_guess(self) -> LidarTopicGuess:
        """The log's LiDAR data packet topics, IMU packet topics set aside."""
        if self._lidar_guess is None:
            self._lidar_guess = guess_lidar_topics(self.log)
        return self._lidar_guess

    def camera_topics(self) -> CameraProbe:
        """What the first second of every camera topic says (camera fields, frame ids)."""
        if self._cameras is None:
            topics = [t for t, info in self.topics.items() if topic_role(info.msgtype)]
            self._cameras = probe_camera_topics(self.log, topics)
        return self._cameras

    def tf_yaws(self) -> dict[str, float]:
        """Yaw of each child frame in `/tf_static` (deg)."""
        if self._tf_yaws is None:
            self._tf_yaws = tf_static_yaws(self.log)
        return self._tf_yaws

    def family(self, topic: str) -> str | None:
        """The packet family of `topic`'s message type (None: absent, or not packets)."""
        info = self.topics.get(topic)
        return lidar_family(info.msgtype) if info is not None else None

    def packet_vendor(self, topic: str) -> str | None:
        """The vendor the packets on `topic` are: by message type, or by the first Nebula
        scan (None: not packets, or no Nebula scan decodes)."""
        family = self.family(topic)
        if family != "nebula":
            return family
        if topic not in self._vendors:
            self._vendors[topic] = self._first_nebula_vendor(topic)
        return self._vendors[topic]

    def _first_nebula_vendor(self, topic: str) -> str | None:
        for msg in self.log.messages([topic]):
            chunk = decode_scan("nebula", msg, 0)
            if chunk is not None:
                return chunk.timing.vendor
        return None

    def ouster_metadata(self, metadata_topic: str) -> ouster.OusterMetadata:
        """The Ouster sensor metadata on `metadata_topic` (its first message).

        Raises NoDataError where the topic holds no message.
        """
        meta = self._ouster.get(metadata_topic)
        if meta is None:
            meta = self._ouster[metadata_topic] = read_ouster_metadata(self.log, metadata_topic)
        return meta


def probe_of(log: LogReader | LogProbe) -> LogProbe:
    """`log`'s probe: the one given, or a new one of the open log."""
    return log if isinstance(log, LogProbe) else LogProbe(log)
