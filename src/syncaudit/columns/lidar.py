"""LiDAR columns: per revolution (from the tracker), the clock report, and a topic's whole
reduced timing (`LidarScan`), as `lidar.scan` makes them and the analysis reads them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True, slots=True)
class RevolutionColumns:
    """One row per complete or partial revolution, split at the zero-crossing azimuth."""

    zero_crossing_sensor_ns: NDArray[np.int64]
    """(r,) sensor time at which the beam crossed the zero-crossing azimuth."""
    omega_deg_s: NDArray[np.float64]
    """(r,) mean angular velocity over the revolution (from time/azimuth trajectory)."""
    packets: NDArray[np.int64]
    """(r,) packets whose first block lies in the revolution."""
    dropped_packets: NDArray[np.int64]
    """(r,) packets missing inside the revolution, from gaps in the packet cadence."""
    crossing_sensor_ns: NDArray[np.int64]
    """(r, k) sensor time at which the beam crossed each target azimuth (-1 if not seen)."""
    target_azimuth_deg: NDArray[np.float64]
    """(k,) the target azimuths (absolute, degrees) the crossings refer to."""
    zero_packet_sensor_ns: NDArray[np.int64]
    """(r,) sensor time stamp of the packet in which the zero crossing fell."""
    zero_packet_driver_ns: NDArray[np.int64]
    """(r,) driver stamp (242) of that packet."""

    @property
    def count(self) -> int:
        """Number of revolutions."""
        return int(self.zero_crossing_sensor_ns.shape[0])


@dataclass(frozen=True, slots=True)
class ClockReport:
    """What the driver-minus-sensor differences say about the two clocks and t1."""

    packets: int
    raw_min_ns: int
    raw_median_ns: int
    raw_max_ns: int
    raw_mean_ns: float
    synchronised: bool
    offset_ns: int
    """Host minus sensor clock: 0 when synchronised, else the minimum-filter estimate."""
    t1_mean_ns: float
    """Mean t1 after removing `offset_ns`; with an estimated offset this is the spread."""
    t1_p50_ns: float
    t1_p99_ns: float
    t1_std_ns: float


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
    wrap_blocks: int = 0
    """Blocks whose azimuth read 36000 (real Velodyne sensors write it at the wrap), taken
    as 0 (modulo 36000, as ros-drivers/velodyne does)."""
    product_id_model: str = ""
    """The model the packets' product byte names where `model` (from the packet cadence or
    the rig) differs from it."""
    decoder_notes: tuple[str, ...] = ()
    """What the decoder derived rather than read (older Ouster metadata), warned about."""
    whole_turns: int = 0
    """Whole turns the packets sweep, first sample to last: the revolutions `info` and
    `audit` report, whatever the zero azimuth (zero crossings depend on it)."""

    @property
    def rpm_disagreement(self) -> float:
        """(measured - declared) / declared rotation rate; NaN when either is unknown."""
        if not (self.declared_rpm > 0) or not np.isfinite(self.rpm):
            return float("nan")
        return (self.rpm - self.declared_rpm) / self.declared_rpm

    @property
    def warnings(self) -> list[str]:
        """What the topic's own packets say is wrong with the decoded timing."""
        notes = [f"{self.topic}: {note}" for note in self.decoder_notes]
        if self.product_id_model:
            notes.append(
                f"{self.topic}: the product byte says {self.product_id_model} but the packets "
                f"are timed as a {self.model} (their cadence, or the rig's lidar.model): "
                "early VLP-16 firmware wrote the HDL-32E's id"
            )
        off = self.rpm_disagreement
        if not abs(off) > RPM_TOLERANCE:
            return notes
        source = _DECLARED_BY.get(self.vendor, "the packets")
        notes.append(
            f"{self.topic}: decoded rotation {self.rpm:.2f} RPM disagrees with the "
            f"{self.declared_rpm:.0f} RPM of {source} ({off:+.1%}): revolutions, "
            "packets/rev and drops are suspect (wrong return-mode grouping or packet clock?)"
        )
        return notes

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
