"""What `info` reads of a log's LiDAR point clouds, and whether they agree with its packets.

A cloud topic is scanned as the audit scans it (`lidar.cloud_scan.scan_cloud`, the rig's
cloud settings or the +X azimuth of the packets' vendor). Where the log also holds the
packets of a LiDAR, the clouds' zero crossings are compared with the packets': a driver
whose per-point times are wrong (an offset, a stamp marking the other end, times relative
to each packet) is a real finding, reported as a warning with the measured difference.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from syncaudit.audit.plan import cloud_settings
from syncaudit.camera.azimuth import X_AXIS_AZIMUTH_DEG
from syncaudit.columns.lidar import LidarScan
from syncaudit.lidar.cloud_samples import CloudSettings
from syncaudit.lidar.cloud_scan import scan_cloud
from syncaudit.logs import LogReader
from syncaudit.rig import Rig

__all__ = ["AGREE_US", "CloudAgreement", "cloud_agreement", "info_cloud_scan"]

AGREE_US = 20.0
"""Clouds and packets agree when their zero crossings differ by no more than this (us):
~0.07 deg at 600 rpm, far above the sector sampling's sub-microsecond error, far below a
packet's 1.3 ms (a wrong stamp convention or per-packet times move it by much more)."""

LEAD_MS = 1.0
"""Clouds whose times lie more than this after the packets' (by arrival) disagree."""


def info_cloud_scan(
    log: LogReader, topic: str, rig: Rig | None, packet_vendor: str | None, jobs: int
) -> tuple[LidarScan, list[str]]:
    """Scan a cloud topic as the audit would (rig settings, else the packets' vendor's +X)."""
    if rig is not None and rig.lidar.topic == topic:
        settings = cloud_settings(rig)
    else:
        settings = CloudSettings(
            x_axis_azimuth_deg=X_AXIS_AZIMUTH_DEG.get(packet_vendor or "", 0.0),
            vendor=packet_vendor or "cloud",
        )
    zero = rig.lidar.zero_azimuth_deg if rig else 0.0
    return scan_cloud(log, topic, settings, zero_azimuth_deg=zero, jobs=jobs)


@dataclass(frozen=True, slots=True)
class CloudAgreement:
    """Clouds' zero crossings against the packets': how many pair, and the differences."""

    cloud_topic: str
    packet_topic: str
    paired: int
    median_us: float
    max_us: float
    arrival_lead_ms: float = 0.0
    """How much earlier than the packets the clouds arrive, relative to their own sensor
    times (packets' median driver-minus-sensor less the clouds' log-minus-last-point).
    A cloud is published after its last packet, so this is <= 0 unless its times are
    later than its points were measured (e.g. a whole turn, which crossings cannot tell)."""

    @property
    def agrees(self) -> bool:
        """Every paired crossing within AGREE_US, and no cloud times after its arrival."""
        return self.paired > 0 and self.max_us <= AGREE_US and self.arrival_lead_ms <= LEAD_MS

    def note(self) -> str:
        """One line for `info`'s warnings."""
        if self.paired == 0:
            return (
                f"{self.cloud_topic}: no zero crossing of the clouds lies near one of "
                f"{self.packet_topic}: its per-point times do not match the packets"
            )
        head = f"{self.cloud_topic}: per-point times vs the packets of {self.packet_topic}"
        numbers = (
            f"{self.paired} zero crossings, median {self.median_us:+.1f} us, "
            f"max |{self.max_us:.1f}| us, clouds arrive {-self.arrival_lead_ms:+.1f} ms "
            "after the packets' latency"
        )
        if self.agrees:
            return f"{head} agree ({numbers})"
        return (
            f"{head} DISAGREE ({numbers}; more than {AGREE_US:g} us): the cloud driver's "
            "times (or what its header stamp marks) are wrong; audit the packets"
        )


def cloud_agreement(clouds: LidarScan, packets: LidarScan) -> CloudAgreement:
    """Pair each cloud zero crossing with the nearest packet one (within half a turn)."""
    a = packets.revolutions.zero_crossing_sensor_ns
    b = clouds.revolutions.zero_crossing_sensor_ns
    if a.size == 0 or b.size == 0:
        return CloudAgreement(clouds.topic, packets.topic, 0, float("nan"), float("nan"))
    idx = np.clip(np.searchsorted(a, b), 1, max(a.size - 1, 1))
    left, right = a[idx - 1], a[np.minimum(idx, a.size - 1)]
    nearest = np.where(np.abs(b - left) <= np.abs(right - b), left, right)
    diff = (b - nearest).astype(np.float64)
    period = float(np.median(np.diff(a))) if a.size > 1 else float("inf")
    close = np.abs(diff) < period / 2
    if not close.any():
        return CloudAgreement(clouds.topic, packets.topic, 0, float("nan"), float("nan"))
    d_us = diff[close] / 1e3
    lead_ms = 0.0
    if clouds.clock is not None and packets.clock is not None:
        lead_ms = (packets.clock.raw_median_ns - clouds.clock.raw_median_ns) / 1e6
    return CloudAgreement(
        clouds.topic,
        packets.topic,
        int(close.sum()),
        float(np.median(d_us)),
        float(np.max(np.abs(d_us))),
        lead_ms,
    )
