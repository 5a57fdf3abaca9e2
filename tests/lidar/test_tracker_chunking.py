"""The revolution tracker's result does not depend on how the packets are cut into chunks.

A block whose azimuth is exactly a crossing azimuth (azimuths are quantised, so this
happens every few turns) must fall on the same side of the crossing whether the packets
came one scan at a time, all at once or split anywhere: the unwrapped angle is exact.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sample_chunks import split_samples
from syncaudit.columns.lidar import RevolutionColumns
from syncaudit.lidar.revolutions import RevolutionTracker
from syncaudit.lidar.samples import PacketSamples, concat_samples, packet_samples
from syncaudit.lidar.stream import iter_packet_chunks
from syncaudit.logs import open_log
from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log


def _track(
    chunks: list[PacketSamples], zero_deg: float, targets: tuple[float, ...]
) -> RevolutionColumns:
    tracker = RevolutionTracker(zero_azimuth_deg=zero_deg, target_azimuth_deg=targets)
    for chunk in chunks:
        tracker.feed(chunk)
    return tracker.finish()


def _assert_same(a: RevolutionColumns, b: RevolutionColumns) -> None:
    for name in RevolutionColumns.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def _check_invariance(per_scan: list[PacketSamples]) -> None:
    whole = concat_samples(per_scan)
    # A zero azimuth and a target exactly on recorded block azimuths: the tie case.
    middle = whole.sample_azimuth_deg.size // 2
    zero_deg = float(whole.sample_azimuth_deg[middle])
    targets = (float(whole.sample_azimuth_deg[middle + 7]), 90.0, 271.3)
    reference = _track(per_scan, zero_deg, targets)
    assert reference.count >= 3
    assert np.all(reference.crossing_sensor_ns[:-1] > 0)  # the last turn may end early
    _assert_same(_track([whole], zero_deg, targets), reference)
    rng = np.random.default_rng(5)
    cuts = np.sort(rng.choice(np.arange(1, whole.n_packets), size=25, replace=False))
    pieces, rest, done = [], whole, 0
    for cut in cuts.tolist():
        head, rest = split_samples(rest, cut - done)
        pieces.append(head)
        done = cut
    pieces.append(rest)
    _assert_same(_track(pieces, zero_deg, targets), reference)


@pytest.mark.parametrize(
    ("folder", "bag", "topic"),
    [
        ("velodyne_vlp16", "1673400471837873222", "/velodyne_packets"),
        ("hesai_40p", "1673400149412331409", "/pandar_packets"),
    ],
)
def test_real_recordings_chunking_invariant(
    lidar_data: Path, folder: str, bag: str, topic: str
) -> None:
    with open_log(lidar_data / folder / bag) as log:
        per_scan = [
            packet_samples(c.timing, c.driver_stamp_ns) for c in iter_packet_chunks(log, topic)
        ]
    _check_invariance(per_scan)


def test_long_simulated_log_chunking_invariant(tmp_path: Path) -> None:
    """Hundreds of turns: a float sum of steps would drift off the exact crossing angles."""
    out = tmp_path / "log.mcap"
    simulate_sync_log(out, SyncSimConfig(seed=7, duration_s=30.0, lidar_model="VLP-16"))
    with open_log(out) as log:
        topic = next(t.name for t in log.topics.values() if t.msgtype.startswith("velodyne"))
        per_scan = [
            packet_samples(c.timing, c.driver_stamp_ns) for c in iter_packet_chunks(log, topic)
        ]
    _check_invariance(per_scan)
