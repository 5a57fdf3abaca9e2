"""packet_samples: the shortcut for packets whose blocks all agree gives the exact test's answer.

Most packets have every block within a few degrees of block 0, so packet_samples skips the
exact test (a float remainder per block) for them. These tests pin that the shortcut picks
the same blocks, outliers included, on inputs built to sit on its edges: spans just inside
and outside its 29-degree bound and the exact test's 30 / 330 degrees, across 0/360, with
NaN and infinite azimuths (Hesai and Ouster decoders produce those).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from numpy.typing import NDArray

from syncaudit.lidar import samples as s
from syncaudit.lidar.packets import PacketTiming


def _edge_azimuths(rng: np.random.Generator, n: int, b: int) -> NDArray[np.float64]:
    """(n, b) azimuths whose offsets from block 0 sit on and around every threshold."""
    cuts = [0.0, 0.2, 29.0, 30.0, 180.0, 330.0, 331.0, 359.8, 360.0]
    eps = [0.0, 1e-13, -1e-13, 1e-6, -1e-6]
    deltas = np.array([sign * (c + e) for c in cuts for e in eps for sign in (1, -1)])
    az0 = rng.choice([0.0, 1e-300, 29.0, 123.4, 330.0, 359.99, 360.0 - 1e-13], size=(n, 1))
    az = az0 + rng.choice(deltas, size=(n, b))
    calm = rng.random(n) < 0.5  # packets with every block close to block 0
    az[calm] = az0[calm] + rng.uniform(-2.0, 2.0, size=(n, b))[calm]
    az[:, 0] = az0[:, 0]
    az[rng.random((n, b)) < 0.03] = np.nan
    az[rng.random((n, b)) < 0.01] = np.inf
    az[rng.random((n, b)) < 0.01] = -np.inf
    wrap = rng.random(n) < 0.5
    with np.errstate(invalid="ignore"):  # inf % 360
        az[wrap] = np.mod(az[wrap], 360.0)
    return az


@pytest.mark.parametrize("b", [1, 2, 10, 12, 16, 32])
def test_shortcut_matches_exact_test(b: int) -> None:
    rng = np.random.default_rng(b)
    for _ in range(20):
        az = _edge_azimuths(rng, 200, b)
        near = s._near_first_block(az)
        assert near.any() and not near.all()  # both paths, in one call
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # NaN / inf in the exact test
            pick, has, outliers = s._sample_blocks(az)
            want_pick, want_has, want_outliers = s._sample_blocks_exact(az)
        np.testing.assert_array_equal(pick, want_pick)
        np.testing.assert_array_equal(has, want_has)
        assert outliers == want_outliers


def test_shortcut_only_where_every_block_is_surely_sane() -> None:
    az = np.array(
        [
            [10.0, 12.0, 38.9, 10.0],  # 28.9 deg from block 0: shortcut
            [10.0, 12.0, 39.0, 10.0],  # 29 deg: exact test (still sane)
            [359.0, 0.5, 1.0, 358.0],  # across 0/360: shortcut
            [5.0, 5.1, np.nan, 5.2],  # NaN: exact test
            [5.0, 5.1, np.inf, 5.2],  # inf: exact test
            [np.nan, 5.1, 5.2, 5.3],  # block 0 missing: exact test
        ]
    )
    assert s._near_first_block(az).tolist() == [True, False, True, False, False, False]


def _timing(az: NDArray[np.float64], modes: list[int]) -> PacketTiming:
    n, b = az.shape
    stamps = np.arange(n, dtype=np.int64) * 1_000_000
    block_time = stamps[:, None] + np.arange(b, dtype=np.int64) * 10_000
    return PacketTiming(
        vendor="hesai",
        model="Pandar40P",
        sensor_time_ns=stamps,
        block_azimuth_deg=az,
        block_time_ns=block_time,
        return_mode=np.array(modes, dtype=np.uint8),
        dual_return=np.zeros(n, dtype=bool),
    )


def test_packet_samples_outliers_and_missing_blocks() -> None:
    az = np.array(
        [
            [10.0, 10.2, 10.4, 10.6],
            [10.8, 11.0, 200.0, 11.4],  # one outlier block
            [np.nan, 11.6, 11.8, 12.0],  # first block missing
            [np.nan, np.nan, np.nan, np.nan],  # no block at all
            [12.8, 13.0, 13.2, 13.4],
        ]
    )
    timing = _timing(az, [0x37] * 5)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        got = s.packet_samples(timing, timing.sensor_time_ns + 5)
    assert got.outlier_blocks == 1
    assert got.sample_packet.tolist() == [0, 0, 1, 1, 2, 2, 4, 4]
    assert got.sample_azimuth_deg.tolist() == [10.0, 10.6, 10.8, 11.4, 11.6, 12.0, 12.8, 13.4]
    assert (
        got.sample_time_ns.tolist()
        == timing.block_time_ns[[0, 0, 1, 1, 2, 2, 4, 4], [0, 3, 0, 3, 1, 3, 0, 3]].tolist()
    )
    assert got.return_modes == frozenset({0x37})
    assert s.packet_samples(
        _timing(az, [0x37, 0x38, 0x37, 0x37, 0x39]), got.driver_stamp_ns
    ).return_modes == frozenset({0x37, 0x38, 0x39})
