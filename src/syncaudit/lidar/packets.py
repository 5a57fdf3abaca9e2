"""The columns every vendor decoder produces: per packet, per block, time and azimuth only.

Convention: times are int64 nanoseconds since the Unix epoch in the sensor's clock,
azimuths are float64 degrees in [0, 360) as the vendor defines them (the rig says the
direction of rotation). A *block* is the vendor's unit that carries one azimuth
(Velodyne data block, Hesai block, Ouster measurement column).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True, slots=True)
class PacketTiming:
    """Timing of n packets of one sensor with b blocks each."""

    vendor: str
    """'velodyne', 'hesai' or 'ouster'."""
    model: str
    """Model name as the vendor writes it, e.g. 'VLP-16', 'Pandar40P', 'OS-1-128'."""
    sensor_time_ns: NDArray[np.int64]
    """(n,) the packet's own time stamp, full epoch, sensor clock."""
    block_azimuth_deg: NDArray[np.float64]
    """(n, b) azimuth of each block in degrees, [0, 360)."""
    block_time_ns: NDArray[np.int64]
    """(n, b) sensor time at which each block's azimuth was measured, full epoch: the
    block's first firing (on VLS-128, whose banks share the sequence-start azimuth, the
    first firing of the block's firing sequence)."""
    return_mode: NDArray[np.uint8]
    """(n,) the vendor's return-mode code as found in the packet."""
    dual_return: NDArray[np.bool_]
    """(n,) True where the packet carries two returns per firing (blocks repeat azimuths)."""
    motor_rpm: NDArray[np.float64] | None = None
    """(n,) the rotation rate the sensor declares for each packet, RPM (Hesai: the tail's
    Motor Speed field; Ouster: the metadata's lidar_mode); None where the vendor's packets
    carry none (Velodyne)."""
    wrap_blocks: int = 0
    """Blocks whose azimuth field read 36000 (the wrap, as real Velodyne sensors write it),
    taken modulo 36000 as ros-drivers/velodyne does."""
    product_id_model: str = ""
    """The model the packets' product byte names where `model` differs from it (early
    VLP-16 firmware writes the HDL-32E's id; the packet cadence or the rig told them apart)."""
    notes: tuple[str, ...] = ()
    """What the decoder derived rather than read (e.g. fields older Ouster metadata lacks)."""

    @property
    def n_packets(self) -> int:
        """Number of packets."""
        return int(self.sensor_time_ns.shape[0])

    def __post_init__(self) -> None:
        n = self.sensor_time_ns.shape[0]
        if self.block_azimuth_deg.shape != self.block_time_ns.shape:
            raise ValueError("block_azimuth_deg and block_time_ns differ in shape")
        if self.block_azimuth_deg.shape[:1] != (n,) or self.return_mode.shape != (n,):
            raise ValueError("per-packet columns differ in length")
        if self.dual_return.shape != (n,):
            raise ValueError("dual_return differs in length")
        if self.motor_rpm is not None and self.motor_rpm.shape != (n,):
            raise ValueError("motor_rpm differs in length")
