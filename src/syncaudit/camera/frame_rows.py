"""What the reader makes of each per-frame camera message: an image, exposure or trigger row.

A `CameraRowExtractor` is the `logs.parallel.Extractor` of camera topics: it names which
topic holds which kind of row for which camera, and turns each message into one
(kind, topic, row) item, in worker processes where the log allows. Of an image only its
header is read (`IMAGE_PREFIX_BYTES`); exposure and trigger messages go through the struct
readers of `camera.cdr_fast`, else the log's own type definitions (rosbags).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from syncaudit.camera.cdr_fast import has_fast_reader, read_fast
from syncaudit.camera.extract import exposure_row, image_row, trigger_row
from syncaudit.logs import LogReader, RawMessage

__all__ = ["IMAGE_PREFIX_BYTES", "CameraItem", "CameraRowExtractor"]

IMAGE_PREFIX_BYTES = 256
"""Bytes of an image payload the audit reads: its header (stamp, ROS 1 seq) lies in the
first 12-16; the rest (pixels) is never looked at, and readers that can skip it do."""

CameraItem = tuple[str, str, Any]
"""(kind, topic, row): kind is 'image', 'exposure' or 'trigger' (`camera.routing.KINDS`)."""


@dataclass(frozen=True, slots=True)
class CameraRowExtractor:
    """Which camera topics to read and whose rows each holds; picklable for workers.

    A camera of "" marks a topic several cameras share: the router gives each of its rows
    to the camera the message names.
    """

    images: dict[str, str] = field(default_factory=dict)
    """image topic -> camera."""
    exposures: dict[str, tuple[str, str]] = field(default_factory=dict)
    """exposure topic -> (camera, stamp semantics)."""
    triggers: dict[str, str] = field(default_factory=dict)
    """trigger topic -> camera."""

    @property
    def topics(self) -> list[str]:
        """Every camera topic read."""
        return sorted({*self.images, *self.exposures, *self.triggers})

    def prefix_bytes(self, topic: str) -> int:
        """Of an image, its header only; other messages whole."""
        return IMAGE_PREFIX_BYTES if topic in self.images else 0

    def rosbags_encodings(self, log: LogReader) -> set[str]:
        """Encodings of exposure and trigger messages no struct reader reads."""
        infos = [log.topics[t] for t in (*self.exposures, *self.triggers) if t in log.topics]
        return {i.encoding for i in infos if not has_fast_reader(i.msgtype, i.encoding)}

    def extract(self, msg: RawMessage, log: LogReader) -> CameraItem | None:
        """The row one camera message contributes (None: not a topic of the extractor)."""
        topic = msg.topic
        if topic in self.images:
            return ("image", topic, image_row(msg))
        if topic in self.exposures:
            camera, semantics = self.exposures[topic]
            return ("exposure", topic, exposure_row(msg, _fields(msg, log), camera, semantics))
        if topic in self.triggers:
            return ("trigger", topic, trigger_row(msg, _fields(msg, log), self.triggers[topic]))
        return None


def _fields(msg: RawMessage, log: LogReader) -> Any:
    """A message's fields: by struct for the known per-frame types, else through rosbags."""
    fast = read_fast(msg.data, msg.msgtype, msg.encoding)
    return fast if fast is not None else log.deserialize(msg)
