"""One pass over a PointCloud2 LiDAR topic: the packet path's revolutions, from clouds.

`CloudExtractor` is what `logs.parallel` makes of each cloud message (in worker processes
where the log allows): its sectors as packet samples (`lidar.cloud_samples`). `CloudFeeder`
folds them, in log order, into the packet path's `LidarScanner`, so revolutions, zero and
target crossings, RPM, gaps and the clock check are the packet path's own; it also checks
what the header stamps mark (first or last point) against the clouds' own times.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from syncaudit.columns.lidar import LidarScan
from syncaudit.lidar.cloud_samples import CloudSamples, CloudSettings, cloud_samples
from syncaudit.lidar.scan import LidarScanner
from syncaudit.logs import LogReader, RawMessage
from syncaudit.logs.parallel import WholeMessages, iter_items

__all__ = ["CLOUD_TYPES", "CloudExtractor", "CloudFeeder", "is_cloud_type", "scan_cloud"]

CLOUD_TYPES = frozenset({"sensor_msgs/msg/PointCloud2"})
OVERLAP_FRACTION = 0.5
EARLY_CLOUDS = 64
"""Clouds whose arrival is checked against their own times (the first of the topic)."""
EARLY_MIN_NS = 1_000_000
"""A cloud logged more than this before its last point is from the future."""
"""Consecutive clouds overlapping by more than this part of a cloud: stamps mark the end."""


def is_cloud_type(msgtype: str) -> bool:
    """True for the point-cloud message types syncaudit reads LiDAR timing from."""
    return msgtype in CLOUD_TYPES


@dataclass(frozen=True, slots=True)
class CloudExtractor(WholeMessages):
    """What `logs.parallel` makes of one cloud topic's messages (picklable)."""

    settings: CloudSettings

    def extract(self, msg: RawMessage, log: LogReader) -> CloudSamples | None:
        """The sectors of one cloud."""
        return cloud_samples(msg, self.settings)


@dataclass(slots=True)
class CloudFeeder:
    """Feeds clouds' sectors to a LidarScanner and notes what their times say."""

    scanner: LidarScanner
    settings: CloudSettings
    clouds: int = 0
    points: int = 0
    time_field: str = ""
    overlaps: int = 0
    _previous: tuple[int, int] | None = None
    _early: list[tuple[int, int]] = field(default_factory=list)
    """(log time - last point, cloud span) of the first EARLY_CLOUDS clouds."""
    notes: list[str] = field(default_factory=list)

    def feed(self, cloud: CloudSamples) -> None:
        """Add one cloud (in log order)."""
        self.clouds += 1
        self.points += cloud.points
        self.time_field = cloud.time_field
        if self._previous is not None:
            first, last = self._previous
            span = max(last - first, 1)
            if first < cloud.first_ns and last - cloud.first_ns > OVERLAP_FRACTION * span:
                self.overlaps += 1
        self._previous = (cloud.first_ns, cloud.last_ns)
        if len(self._early) < EARLY_CLOUDS:
            self._early.append((cloud.log_time_ns - cloud.last_ns, cloud.last_ns - cloud.first_ns))
        self.scanner.feed(cloud.samples)

    def finish(self) -> LidarScan:
        """The scan, with a note where the stamps look like they mark the other end."""
        if self.clouds > 1 and self.overlaps > (self.clouds - 1) // 2:
            marks = self.settings.stamp_marks or "first"
            other = "last" if marks == "first" else "first"
            self.notes.append(
                f"{self.scanner.topic}: consecutive clouds overlap in time by more than half "
                f"a cloud ({self.overlaps} of {self.clouds - 1}) with header stamps taken "
                f"as the {marks} point: the driver's stamps likely mark the {other} point "
                f"(set lidar.stamp_marks: {other} in the rig)"
            )
        self.notes.extend(self._arrival_note())
        return self.scanner.finish()

    def _arrival_note(self) -> list[str]:
        """A note where clouds are logged about one cloud before their last point's time:
        times shifted by a whole cloud (a stamp marking the other end) look like that, and
        crossings cannot tell it (they recur every turn)."""
        if len(self._early) < 2:
            return []
        lead_ns = -float(np.median([a for a, _ in self._early]))
        span_ns = float(np.median([s for _, s in self._early]))
        if not (lead_ns > EARLY_MIN_NS and span_ns > 0 and lead_ns < 1.5 * span_ns):
            return []
        marks = self.settings.stamp_marks or "first"
        other = "last" if marks == "first" else "first"
        return [
            f"{self.scanner.topic}: clouds are logged {lead_ns / 1e6:.1f} ms before the "
            f"time of their last point (a cloud spans {span_ns / 1e6:.1f} ms) with header "
            f"stamps taken as the {marks} point: the stamps likely mark the {other} point "
            f"(set lidar.stamp_marks: {other} in the rig), or the LiDAR clock runs ahead "
            "of the host's"
        ]


def scan_cloud(
    log: LogReader,
    topic: str,
    settings: CloudSettings,
    *,
    zero_azimuth_deg: float = 0.0,
    azimuth_increases: bool = True,
    target_azimuth_deg: tuple[float, ...] = (),
    clock_tolerance_ns: int = 50_000_000,
    jobs: int = 1,
) -> tuple[LidarScan, list[str]]:
    """Read a cloud topic once, as the audit reads it, and reduce it to revolutions and
    clock statistics; also the notes on its stamps."""
    scanner = LidarScanner.create(
        topic,
        zero_azimuth_deg=zero_azimuth_deg,
        azimuth_increases=azimuth_increases,
        target_azimuth_deg=target_azimuth_deg,
        clock_tolerance_ns=clock_tolerance_ns,
    )
    feeder = CloudFeeder(scanner, settings)
    for cloud in iter_items(log, CloudExtractor(topic, settings), jobs):
        feeder.feed(cloud)
    return feeder.finish(), feeder.notes
