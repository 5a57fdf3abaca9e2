"""LiDAR packet chunks (PacketSamples) cut anywhere: how tests check that the revolution
tracker's result does not depend on how packets arrive."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from syncaudit.lidar.samples import PacketSamples


def split_samples(samples: PacketSamples, at_packet: int) -> tuple[PacketSamples, PacketSamples]:
    """The packets before `at_packet` and from it on, as two chunks."""
    cut = int(np.searchsorted(samples.sample_packet, at_packet))
    head = replace(
        samples,
        sensor_time_ns=samples.sensor_time_ns[:at_packet],
        driver_stamp_ns=samples.driver_stamp_ns[:at_packet],
        sample_time_ns=samples.sample_time_ns[:cut],
        sample_azimuth_deg=samples.sample_azimuth_deg[:cut],
        sample_packet=samples.sample_packet[:cut],
        outlier_blocks=0,
    )
    tail = replace(
        samples,
        sensor_time_ns=samples.sensor_time_ns[at_packet:],
        driver_stamp_ns=samples.driver_stamp_ns[at_packet:],
        sample_time_ns=samples.sample_time_ns[cut:],
        sample_azimuth_deg=samples.sample_azimuth_deg[cut:],
        sample_packet=samples.sample_packet[cut:] - at_packet,
    )
    return head, tail
