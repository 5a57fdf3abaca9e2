"""One pass over a LiDAR topic: revolutions, cadence, clock — everything timing needs."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from syncaudit.columns.lidar import RevolutionColumns
from syncaudit.lidar.clock import ClockEstimator, ClockReport
from syncaudit.lidar.revolutions import RevolutionTracker
from syncaudit.lidar.samples import PacketSamples, concat_samples
from syncaudit.lidar.stream import packet_family
from syncaudit.logs import LogReader


@dataclass(frozen=True, slots=True)
class LidarScan:
    """The reduced timing of one LiDAR topic."""

    topic: str
    vendor: str
    model: str
    scans: int
    packets: int
    return_modes: tuple[int, ...]
    dual_return: bool
    revolutions: RevolutionColumns
    clock: ClockReport | None
    omega_blocks_deg_s: float
    """Angular velocity from block to block, for logs shorter than two revolutions."""
    cropped_sector: tuple[float, float, int] | None
    """(angle where recording stops, packets missing per turn, revolutions) of a FOV crop."""
    outlier_blocks: int
    declared_rpm: float = float("nan")
    """Mean rotation rate the packets themselves declare (Hesai tail motor speed, Ouster
    lidar_mode), RPM; NaN where the vendor's packets carry none (Velodyne)."""

    @property
    def rpm_disagreement(self) -> float:
        """(measured - declared) / declared rotation rate; NaN when either is unknown."""
        if not (self.declared_rpm > 0) or not np.isfinite(self.rpm):
            return float("nan")
        return (self.rpm - self.declared_rpm) / self.declared_rpm

    @property
    def warnings(self) -> list[str]:
        """What the topic's own packets say is wrong with the decoded timing."""
        off = self.rpm_disagreement
        if not abs(off) > RPM_TOLERANCE:
            return []
        source = _DECLARED_BY.get(self.vendor, "the packets")
        return [
            f"{self.topic}: decoded rotation {self.rpm:.2f} RPM disagrees with the "
            f"{self.declared_rpm:.0f} RPM of {source} ({off:+.1%}): revolutions, "
            "packets/rev and drops are suspect (wrong return-mode grouping or packet clock?)"
        ]

    @property
    def rpm(self) -> float:
        """Median measured rotation rate (revolutions per minute)."""
        omega = self.revolutions.omega_deg_s
        omega = omega[np.isfinite(omega)]
        return float(np.median(omega) / 6.0) if omega.size else self.omega_blocks_deg_s / 6.0

    @property
    def packets_per_revolution(self) -> float:
        """Median packets in a complete revolution (first and last are partial)."""
        counts = self.revolutions.packets[1:-1]
        return float(np.median(counts)) if counts.size else float("nan")

    @property
    def dropped_packets(self) -> int:
        """Packets missing from gaps in the packet cadence."""
        return int(self.revolutions.dropped_packets.sum())


RPM_TOLERANCE = 0.03
"""Relative disagreement between the decoded and the declared rotation rate that warns:
motor-speed fields hold whole RPM and the motor hunts by well under 1 %, while a wrong
block grouping or packet clock is off by tens of percent."""

_DECLARED_BY = {"hesai": "the packets' motor-speed field", "ouster": "the metadata's lidar_mode"}
"""Where each vendor's declared rotation rate comes from, for the warning."""

FEED_PACKETS = 4096
"""Packets gathered before the tracker and clock run: their numpy work per call is then
amortised over several scans (or many single-packet messages), memory still bounded."""


@dataclass(slots=True)
class LidarScanner:
    """Reduces decoded packet chunks, fed in log order, to a LidarScan."""

    topic: str
    tracker: RevolutionTracker
    clock: ClockEstimator
    vendor: str = ""
    model: str = ""
    scans: int = 0
    packets: int = 0
    modes: set[int] = field(default_factory=set)
    dual: bool = False
    declared_rpm_sum: float = 0.0
    declared_rpm_count: int = 0
    _pending: list[PacketSamples] = field(default_factory=list)
    _pending_packets: int = 0

    @classmethod
    def create(
        cls,
        topic: str,
        *,
        zero_azimuth_deg: float = 0.0,
        azimuth_increases: bool = True,
        target_azimuth_deg: tuple[float, ...] = (),
        clock_tolerance_ns: int = 50_000_000,
    ) -> LidarScanner:
        """A scanner for one topic with the rig's zero crossing and target azimuths."""
        tracker = RevolutionTracker(
            zero_azimuth_deg=zero_azimuth_deg,
            direction=1 if azimuth_increases else -1,
            target_azimuth_deg=target_azimuth_deg,
        )
        return cls(topic, tracker, ClockEstimator(tolerance_ns=clock_tolerance_ns))

    def feed(self, samples: PacketSamples, messages: int = 1) -> None:
        """Add one scan message (or a batch of `messages` single-packet messages)."""
        self.vendor, self.model = samples.vendor, samples.model
        self.scans += messages
        self.packets += samples.n_packets
        self.modes.update(samples.return_modes)
        self.dual = self.dual or samples.dual_return
        self.declared_rpm_sum += samples.declared_rpm_sum
        self.declared_rpm_count += samples.declared_rpm_count
        self._pending.append(samples)
        self._pending_packets += samples.n_packets
        if self._pending_packets >= FEED_PACKETS:
            self._flush()

    def _flush(self) -> None:
        """Run the tracker and the clock over the gathered packets."""
        if not self._pending:
            return
        batch = concat_samples(self._pending)
        self._pending, self._pending_packets = [], 0
        self.tracker.feed(batch)
        self.clock.feed(batch.driver_stamp_ns, batch.sensor_time_ns)

    def finish(self) -> LidarScan:
        """The reduced timing of everything fed."""
        self._flush()
        return LidarScan(
            topic=self.topic,
            vendor=self.vendor,
            model=self.model,
            scans=self.scans,
            packets=self.packets,
            return_modes=tuple(sorted(self.modes)),
            dual_return=self.dual,
            revolutions=self.tracker.finish(),
            clock=self.clock.finish(),
            omega_blocks_deg_s=self.tracker.omega_blocks_deg_s,
            cropped_sector=self.tracker.cropped_sector(),
            outlier_blocks=self.tracker.outlier_blocks,
            declared_rpm=self.declared_rpm_sum / self.declared_rpm_count
            if self.declared_rpm_count
            else float("nan"),
        )


def scan_lidar(
    log: LogReader,
    topic: str,
    *,
    zero_azimuth_deg: float = 0.0,
    azimuth_increases: bool = True,
    target_azimuth_deg: tuple[float, ...] = (),
    clock_tolerance_ns: int = 50_000_000,
    ouster_metadata_topic: str | None = None,
    jobs: int = 1,
) -> LidarScan:
    """Read the topic once, as the audit reads it (`collect.iter_items`: `jobs` worker
    processes where the log allows, one scan message at a time), and reduce it to
    revolutions and clock statistics."""
    from syncaudit.audit.collect import ExtractPlan, iter_items

    family, meta = packet_family(log, topic, ouster_metadata_topic)
    scanner = LidarScanner.create(
        topic,
        zero_azimuth_deg=zero_azimuth_deg,
        azimuth_increases=azimuth_increases,
        target_azimuth_deg=target_azimuth_deg,
        clock_tolerance_ns=clock_tolerance_ns,
    )
    for _kind, _topic, samples in iter_items(log, ExtractPlan(topic, family, meta), jobs):
        scanner.feed(samples)
    return scanner.finish()
