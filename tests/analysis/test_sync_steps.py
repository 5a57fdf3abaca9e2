"""Each step of the camera analysis on hand-built tables (style.md, theme 7)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from syncaudit.analysis.offset import host_offset_ns
from syncaudit.analysis.pairing import PHASE_FROM_TRACKER, PHASE_FROM_TRIGGER, pair_revolutions
from syncaudit.analysis.stamps import MISSING_NS, delta_ns, nullable, stamps_ns
from syncaudit.analysis.sync import _errors, _t_l_ns
from syncaudit.audit.run import audit_log
from syncaudit.columns.lidar import RevolutionColumns
from syncaudit.columns.table import Table, int_column
from syncaudit.rig import load_rig

T0 = 1_700_000_000_000_000_123
PERIOD = 100_000_000
PACKET = 1_327_000
SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"


def _revolutions(count: int = 5) -> RevolutionColumns:
    """`count` revolutions at 600 rpm; camera centre 30 ms after each zero crossing."""
    zero = T0 + PERIOD * np.arange(count, dtype=np.int64)
    return RevolutionColumns(
        zero_crossing_sensor_ns=zero,
        omega_deg_s=np.full(count, 3600.0),
        packets=np.full(count, 75, dtype=np.int64),
        dropped_packets=np.zeros(count, dtype=np.int64),
        crossing_sensor_ns=(zero + 30_000_000)[:, None],
        target_azimuth_deg=np.array([108.0]),
        zero_packet_sensor_ns=zero - 400_000,
        zero_packet_driver_ns=zero - 100_000,
    )


def _frames(packet_ns: list[int | None], t_l_ns: list[int]) -> tuple[Table, np.ndarray]:
    frames = Table({"trig_lidar_packet_ns": int_column(packet_ns)})
    return frames, np.array(t_l_ns, dtype=np.int64)


def test_trigger_packet_pairs_with_the_nearest_zero_crossing() -> None:
    revs = _revolutions()
    # Packets 2 after, 3 before, and containing the crossing of revolutions 1, 2, 3.
    packets = [T0 + PERIOD + 2 * PACKET, T0 + 2 * PERIOD - 3 * PACKET, T0 + 3 * PERIOD - 400_000]
    frames, t_l = _frames(packets, [T0 + PERIOD * k + 30_000_000 for k in (1, 2, 3)])
    pairing = pair_revolutions(frames, revs, t_l, target_index=0, offset_ns=0, max_gap_ns=5e7)
    assert pairing.revolution.tolist() == [1, 2, 3]
    assert pairing.packet_phase_ns.tolist() == [-2 * PACKET, 3 * PACKET, 400_000]
    assert pairing.t_rotate_ns.tolist() == [30_000_000.0] * 3
    assert pairing.phase_source() == PHASE_FROM_TRIGGER


def test_frame_without_trigger_packet_pairs_with_the_nearest_crossing() -> None:
    revs = _revolutions()
    offset = 5_000  # host minus sensor
    frames, t_l = _frames([None, None], [T0 + PERIOD * 2 + 31_000_000, T0 + 4_000_000_000])
    pairing = pair_revolutions(frames, revs, t_l, target_index=0, offset_ns=offset, max_gap_ns=5e7)
    assert pairing.revolution.tolist() == [2, -1]  # the second is far from every crossing
    assert pairing.t_estimated_ns[0] == T0 + 2 * PERIOD + 30_000_000 + offset
    assert pairing.t_estimated_ns[1] == MISSING_NS
    assert pairing.packet_phase_ns[0] == 400_000  # the tracker's zero packet
    assert pairing.phase_source() == PHASE_FROM_TRACKER


def test_unset_trigger_packet_time_falls_back_to_the_tracker() -> None:
    frames, t_l = _frames([0, T0 + PERIOD], [T0 + 2 * PERIOD + 31_000_000, T0 + PERIOD + 3e7])
    pairing = pair_revolutions(
        frames, _revolutions(), t_l, target_index=0, offset_ns=0, max_gap_ns=5e7
    )
    assert pairing.revolution.tolist() == [2, 1]
    assert pairing.phase_from_trigger.tolist() == [False, True]
    assert pairing.packet_phase_ns.tolist() == [400_000, 0]


def test_mixed_phase_sources_are_counted() -> None:
    frames, t_l = _frames([T0 + PERIOD, None], [T0 + PERIOD + 3e7, T0 + 2 * PERIOD + 3e7])
    pairing = pair_revolutions(
        frames, _revolutions(), t_l, target_index=0, offset_ns=0, max_gap_ns=5e7
    )
    assert pairing.phase_source() == "mixed: 1 trigger packet, 1 tracker zero packet"


def test_error_beyond_a_quarter_revolution_stays_unpaired() -> None:
    t_est = np.array([T0, T0, T0, MISSING_NS], dtype=np.int64)
    t_l = np.array([T0 + 1_234, T0 - 26_000_000, MISSING_NS, T0], dtype=np.int64)
    errors = _errors(t_l, t_est, period_ns=PERIOD)
    assert errors.paired.tolist() == [True, False, False, False]
    assert errors.signed_ns[0] == 1_234.0 and np.isnan(errors.signed_ns[1])
    assert errors.unpaired == {
        "no exposure metadata": 1,
        "no LiDAR revolution": 1,
        "error beyond a quarter revolution": 1,
    }


def test_t_l_is_exact_integer_mid_exposure() -> None:
    frames = Table(
        {
            "exposure_start_ns": int_column([T0, T0, None]),
            "exposure_duration_ns": int_column([2_000_001, None, 5]),
        }
    )
    assert _t_l_ns(frames).tolist() == [T0 + 1_000_000, MISSING_NS, MISSING_NS]
    assert nullable(_t_l_ns(frames)).tolist() == [T0 + 1_000_000, pd.NA, pd.NA]
    assert delta_ns(stamps_ns(frames, "exposure_start_ns"), np.full(3, T0 - 7)).tolist()[0] == 7.0


def test_offset_snaps_trigger_packets_to_the_packet_grid() -> None:
    """Triggers naming the packet after the zero packet still give the exact offset."""
    from syncaudit.columns.lidar import ClockReport, LidarScan

    revs = _revolutions(6)
    true_offset = -1_234_567_891
    t1 = np.array([280_000, 300_000, 310_000, 295_000, 305_000], dtype=np.int64)
    clock = ClockReport(10_000, 0, true_offset + 300_000, 0, 0.0, False, 0, 0.0, 0.0, 0.0, 0.0)
    scan = LidarScan("/p", "velodyne", "VLP-16", 6, 450, (55,), False, revs, clock, 3600.0, None, 0)
    period = PERIOD * 5 / 375  # the scan's packets per revolution
    packet = revs.zero_packet_sensor_ns[:5] + np.rint(period).astype(np.int64) + true_offset
    offset, how = host_offset_ns(scan, packet, packet + t1)
    assert offset == pytest.approx(true_offset, abs=1)
    assert "packet grid" in how


def test_frames_table_has_no_float_stamps_and_exact_errors() -> None:
    result = audit_log(SAMPLES / "vlp16_short.bag", load_rig(SAMPLES / "vlp16_short.bag.rig.yaml"))
    frames = result.frames()
    stamps = ("t_l_ns", "t_estimated_ns", "revolution_start_ns", "exposure_start_ns")
    for column in (*stamps, "header_stamp_ns"):
        assert str(frames[column].dtype) == "Int64", column
    errors = frames["error_signed_ns"].dropna().to_numpy()
    assert errors.size > 50 and np.mean(errors % 256 == 0) < 0.1
    assert np.array_equal(
        errors, (frames["t_l_ns"] - frames["t_estimated_ns"]).dropna().to_numpy(np.float64)
    )
