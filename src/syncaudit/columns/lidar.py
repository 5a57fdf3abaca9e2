"""LiDAR columns: per packet (from the decoders) and per revolution (from the tracker)."""

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
