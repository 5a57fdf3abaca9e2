"""scan_lidar on every real recording: model, cadence, revolutions, RPM and clock."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from syncaudit.lidar.scan import scan_lidar
from syncaudit.logs import open_log

# (folder, bag path inside it, topic, vendor, model, scans, packets, packets/rev, rpm)
CASES = [
    (
        "velodyne_vlp16",
        "1673400471837873222",
        "/velodyne_packets",
        "velodyne",
        "VLP-16",
        4,
        603,
        150,
    ),
    (
        "velodyne_vlp32",
        "1713492677464078412",
        "/sensing/lidar/front/velodyne_packets",
        "velodyne",
        "VLP-32C",
        5,
        379,
        76,
    ),
    ("hesai_40p", "1673400149412331409", "/pandar_packets", "hesai", "Pandar40P", 4, 1439, 360),
    ("hesai_xt32", "1673400677802009732", "/pandar_packets", "hesai", "PandarXT32", 4, 2000, 500),
]


@pytest.mark.parametrize(
    ("folder", "bag", "topic", "vendor", "model", "scans", "packets", "per_rev"), CASES
)
def test_real_recording_timing(
    lidar_data: Path,
    folder: str,
    bag: str,
    topic: str,
    vendor: str,
    model: str,
    scans: int,
    packets: int,
    per_rev: int,
) -> None:
    with open_log(lidar_data / folder / bag) as log:
        scan = scan_lidar(log, topic)
    assert (scan.vendor, scan.model) == (vendor, model)
    assert scan.scans == scans
    assert scan.packets == packets
    assert scan.rpm == pytest.approx(600.0, abs=1.5)
    assert scan.packets_per_revolution == pytest.approx(per_rev, abs=1)
    assert scan.dropped_packets == 0
    revs = scan.revolutions
    # One revolution starts in every scan after the first; boundaries are a turn apart.
    assert revs.count == scans - 1 or revs.count == scans
    period_ms = np.diff(revs.zero_crossing_sensor_ns) / 1e6
    assert np.all(np.abs(period_ms - 100.0) < 0.5)


def test_vlp16_clock_offset_detected(lidar_data: Path) -> None:
    with open_log(lidar_data / "velodyne_vlp16" / "1673400471837873222") as log:
        scan = scan_lidar(log, "/velodyne_packets")
    clock = scan.clock
    assert clock is not None
    assert not clock.synchronised
    assert clock.raw_median_ns / 1e9 == pytest.approx(1531.18, abs=0.05)
    # With the offset removed by the minimum filter, the latency spread is sub-millisecond.
    assert 0 <= clock.t1_p50_ns < 1e6


def test_hesai_sensor_clocks_not_synchronised(lidar_data: Path) -> None:
    expected_s = {"hesai_40p": 168_685_362.43, "hesai_xt32": 109_375_908.08}
    for folder, offset_s in expected_s.items():
        bag = next(p for p in (lidar_data / folder).iterdir() if p.is_dir())
        with open_log(bag) as log:
            clock = scan_lidar(log, "/pandar_packets").clock
        assert clock is not None and not clock.synchronised
        assert clock.raw_median_ns / 1e9 == pytest.approx(offset_s, abs=0.01)


def test_vlp32_front_crop_is_not_packet_loss(lidar_data: Path) -> None:
    """Autoware records only the front half: the same gap every turn is a crop, not drops."""
    with open_log(lidar_data / "velodyne_vlp32" / "1713492677464078412") as log:
        scan = scan_lidar(log, "/sensing/lidar/front/velodyne_packets")
    assert scan.cropped_sector is not None
    resume_deg, missing_per_turn, revolutions = scan.cropped_sector
    assert resume_deg == pytest.approx(270.4, abs=1.0)
    assert missing_per_turn == pytest.approx(75, abs=2)
    assert revolutions == scan.revolutions.count - 1  # one gap between each pair of scans
    assert scan.dropped_packets == 0
    assert scan.outlier_blocks > 0  # the blocks past 90 deg in each scan's last packet


def test_ouster_single_frame(lidar_data: Path) -> None:
    with open_log(lidar_data / "ouster_os1_512x10" / "512x10_raw.bag") as log:
        scan = scan_lidar(log, "/os_node0/lidar_packets")
    assert (scan.vendor, scan.model, scan.packets) == ("ouster", "OS-0-128", 32)
    # Under two zero crossings: the rate comes from the block trajectory.
    assert scan.rpm == pytest.approx(600.5, abs=0.5)
    assert scan.clock is not None and not scan.clock.synchronised


@pytest.mark.parametrize(
    ("folder", "topic", "declared"),
    [
        ("hesai_40p", "/pandar_packets", 600.0),
        ("hesai_xt32", "/pandar_packets", 599.2),
        ("ouster_os1_512x10", "/os_node0/lidar_packets", 600.0),
        ("velodyne_vlp16", "/velodyne_packets", None),
    ],
)
def test_declared_rotation_rate_agrees(
    lidar_data: Path, folder: str, topic: str, declared: float | None
) -> None:
    """The packets' own motor-speed field (Hesai tail, Ouster lidar_mode) matches the decode."""
    bag = next(
        p for p in sorted((lidar_data / folder).iterdir()) if p.is_dir() or p.suffix == ".bag"
    )
    with open_log(bag) as log:
        scan = scan_lidar(log, topic)
    if declared is None:  # Velodyne data packets carry no motor speed
        assert np.isnan(scan.declared_rpm) and np.isnan(scan.rpm_disagreement)
    else:
        assert scan.declared_rpm == pytest.approx(declared, abs=0.1)
        assert abs(scan.rpm_disagreement) < 0.002
    assert scan.warnings == []
