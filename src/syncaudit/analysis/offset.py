"""Host minus LiDAR clock, for logs whose LiDAR clock is not synchronised with the host."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from syncaudit.analysis.pairing import nearest_index
from syncaudit.columns.lidar import LidarScan


def packet_period_ns(scan: LidarScan) -> float:
    """Mean packet period between the first and the last zero crossing (NaN if unknown).

    Packets seen plus packets missing from cadence gaps, over whole revolutions: exact to
    one packet in the span, so ~0.03 % over 4 s of a VLP-16.
    """
    revs = scan.revolutions
    if revs.count < 2:
        return float("nan")
    count = int(revs.packets[:-1].sum() + revs.dropped_packets[:-1].sum())
    span = int(revs.zero_crossing_sensor_ns[-1] - revs.zero_crossing_sensor_ns[0])
    return span / count if count > 0 and span > 0 else float("nan")


def host_offset_ns(
    scan: LidarScan, packet_ns: NDArray[np.int64], driver_ns: NDArray[np.int64]
) -> tuple[int, str]:
    """Host minus sensor clock: 0 when synchronised, else from triggers or the clock floor.

    `packet_ns` and `driver_ns` are the triggers' checkpoint-240 and -242 stamps (host
    clock) of every camera, aligned, `MISSING_NS`-free. A trigger may name any packet near
    the zero crossing (drivers differ), so the offset is not "trigger packet minus zero
    packet". First, t1 gives it to a few microseconds: every packet's driver-minus-sensor
    difference is offset + t1, and the triggers record t1 of their own packets, so
    offset = median(driver - sensor) - median(trigger t1). Then each trigger packet is
    snapped to the packet grid of its revolution's zero packet (whole packet periods),
    and the offset is the median of what remains: exact where the stamps are.
    """
    clock = scan.clock
    if clock is None or clock.synchronised:
        return 0, "synchronised"
    zero_pkt = scan.revolutions.zero_packet_sensor_ns
    if not packet_ns.size or not zero_pkt.size:
        return clock.offset_ns, "minimum filter (absolute errors uncertain by the t1 floor)"
    if driver_ns.size != packet_ns.size:
        # No trigger t1: assume the triggers name the zero packet (pair by the floor).
        residual = packet_ns - zero_pkt[nearest_index(zero_pkt, packet_ns - clock.offset_ns)]
        return (
            int(np.median(residual)),
            "from trigger packet stamps, assumed to name the zero-crossing packet",
        )
    rough = clock.raw_median_ns - int(np.median(driver_ns - packet_ns))
    residual = packet_ns - zero_pkt[nearest_index(zero_pkt, packet_ns - rough)]
    period = packet_period_ns(scan)
    if not np.isfinite(period):
        return rough, "from the t1 of trigger packets against all packets"
    steps = np.rint((residual - rough) / period)
    residual = residual - np.rint(steps * period).astype(np.int64)
    return int(np.median(residual)), "from trigger packet stamps on the packet grid"
