"""Which PointCloud2 topics of a log are a spinning LiDAR's clouds with per-point times.

A PointCloud2 topic is a LiDAR timing source when its first cloud has a per-point time
field `cloud_fields.cloud_time` knows and an azimuth (the `azimuth` field, or x and y):
a cloud of another kind (a map, a filtered or merged cloud without times) is set aside
with the reason.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from syncaudit.errors import SyncauditError
from syncaudit.lidar.cloud_fields import cloud_time, measured_x_axis_deg
from syncaudit.lidar.cloud_layout import cloud_layout
from syncaudit.lidar.cloud_scan import is_cloud_type
from syncaudit.logs import LogReader

__all__ = ["CloudTopicGuess", "guess_cloud_topics"]


@dataclass(frozen=True, slots=True)
class CloudTopicGuess:
    """The LiDAR cloud topics of a log (sorted by name), their time fields, the others."""

    topics: list[str] = field(default_factory=list)
    time_fields: dict[str, str] = field(default_factory=dict)
    x_axis_deg: dict[str, float | None] = field(default_factory=dict)
    """Packet azimuth of each topic's +X, as its first cloud shows (`measured_x_axis_deg`)."""
    set_aside: dict[str, str] = field(default_factory=dict)


def guess_cloud_topics(log: LogReader, time_field: str | None = None) -> CloudTopicGuess:
    """The PointCloud2 topics whose first cloud carries per-point times and azimuths."""
    guess = CloudTopicGuess()
    for topic in sorted(t.name for t in log.topics.values() if is_cloud_type(t.msgtype)):
        first = next(iter(log.messages([topic])), None)
        if first is None:
            guess.set_aside[topic] = "no message"
            continue
        try:
            layout = cloud_layout(first)
            name = cloud_time(layout, time_field).name
        except SyncauditError as exc:
            guess.set_aside[topic] = str(exc)
            continue
        if "azimuth" not in layout.fields and not {"x", "y"} <= set(layout.fields):
            guess.set_aside[topic] = "no azimuth field and no x, y"
            continue
        guess.topics.append(topic)
        guess.time_fields[topic] = name
        guess.x_axis_deg[topic] = measured_x_axis_deg(layout, first.data)
    return guess
