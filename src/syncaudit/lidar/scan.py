"""One pass over a LiDAR topic: revolutions, cadence, clock — everything timing needs."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from syncaudit.columns.lidar import RevolutionColumns
from syncaudit.lidar.clock import ClockEstimator, ClockReport
from syncaudit.lidar.revolutions import RevolutionTracker
from syncaudit.lidar.stream import iter_packet_chunks
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


def scan_lidar(
    log: LogReader,
    topic: str,
    *,
    zero_azimuth_deg: float = 0.0,
    azimuth_increases: bool = True,
    target_azimuth_deg: tuple[float, ...] = (),
    clock_tolerance_ns: int = 50_000_000,
    ouster_metadata_topic: str | None = None,
    start_ns: int | None = None,
    stop_ns: int | None = None,
) -> LidarScan:
    """Stream the topic once and reduce it to revolutions and clock statistics."""
    tracker = RevolutionTracker(
        zero_azimuth_deg=zero_azimuth_deg,
        direction=1 if azimuth_increases else -1,
        target_azimuth_deg=target_azimuth_deg,
    )
    clock = ClockEstimator(tolerance_ns=clock_tolerance_ns)
    vendor = model = ""
    scans = packets = 0
    modes: set[int] = set()
    dual = False
    for chunk in iter_packet_chunks(log, topic, start_ns, stop_ns, ouster_metadata_topic):
        timing = chunk.timing
        vendor, model = timing.vendor, timing.model
        scans += 1
        packets += timing.n_packets
        modes.update(np.unique(timing.return_mode).tolist())
        dual = dual or bool(timing.dual_return.any())
        tracker.feed(timing, chunk.driver_stamp_ns)
        clock.feed(chunk.driver_stamp_ns, timing.sensor_time_ns)
    return LidarScan(
        topic=topic,
        vendor=vendor,
        model=model,
        scans=scans,
        packets=packets,
        return_modes=tuple(sorted(modes)),
        dual_return=dual,
        revolutions=tracker.finish(),
        clock=clock.finish(),
        omega_blocks_deg_s=tracker.omega_blocks_deg_s,
        cropped_sector=tracker.cropped_sector(),
        outlier_blocks=tracker.outlier_blocks,
    )
