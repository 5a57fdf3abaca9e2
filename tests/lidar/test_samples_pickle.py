"""PacketSamples crosses from reader workers to the parent as one buffer, unchanged.

`PacketSamples.__reduce__` packs the arrays into one bytes object; the parent gets
read-only views of it. Every field must come back with its dtype, shape and values, for
real packets, empty chunks, non-contiguous and other-dtype arrays, whatever the protocol.
"""

from __future__ import annotations

import pickle
from dataclasses import fields, replace
from pathlib import Path

import numpy as np
import pytest

from syncaudit.lidar import samples as s
from syncaudit.lidar.samples import PacketSamples, packet_samples
from syncaudit.lidar.stream import iter_packet_chunks
from syncaudit.logs import open_log


def _assert_identical(got: PacketSamples, want: PacketSamples) -> None:
    for f in fields(PacketSamples):
        a, b = getattr(got, f.name), getattr(want, f.name)
        if isinstance(b, np.ndarray):
            np.testing.assert_array_equal(a, b, strict=True, err_msg=f.name)
            assert a.dtype == b.dtype and a.shape == b.shape, f.name
        else:
            assert a == b and type(a) is type(b), f.name


def test_every_field_is_packed() -> None:
    names = {f.name for f in fields(PacketSamples)}
    assert set(s._ARRAY_FIELDS) | set(s._OTHER_FIELDS) == names
    assert not set(s._ARRAY_FIELDS) & set(s._OTHER_FIELDS)


@pytest.mark.parametrize("protocol", [2, 4, pickle.HIGHEST_PROTOCOL])
def test_real_packets_round_trip(lidar_data: Path, protocol: int) -> None:
    with open_log(lidar_data / "hesai_40p" / "1673400149412331409") as log:
        chunks = [
            packet_samples(c.timing, c.driver_stamp_ns)
            for c in iter_packet_chunks(log, "/pandar_packets")
        ]
    assert chunks and chunks[0].declared_rpm_count > 0
    for chunk in chunks:
        back = pickle.loads(pickle.dumps(chunk, protocol))
        _assert_identical(back, chunk)
        assert not back.sample_time_ns.flags.writeable  # views of the pickled bytes
    # Several in one pickle (a worker's result list) share nothing by mistake.
    many = pickle.loads(pickle.dumps([("lidar", "/t", c) for c in chunks], protocol))
    for (_, _, back), chunk in zip(many, chunks, strict=True):
        _assert_identical(back, chunk)


def test_edge_chunks_round_trip() -> None:
    empty = np.empty(0, dtype=np.int64)
    none = PacketSamples(
        "velodyne", "VLP-16", empty, empty, empty, np.empty(0), empty, frozenset(), False, 0
    )
    _assert_identical(pickle.loads(pickle.dumps(none)), none)
    wide = np.arange(20, dtype=np.int64) * 1_000_003 + 2**62
    odd = PacketSamples(
        "hesai",
        "Pandar40P",
        wide[::2],  # not contiguous
        wide[1::2].astype(np.int32),  # another dtype
        wide[:7],
        np.array([0.0, -0.0, 359.99, np.nan, np.inf, 1e-300, 12.5]),
        np.array([0, 0, 1, 3, 3, 4, 9], dtype=np.int64),
        frozenset({0x37, 0x39}),
        True,
        3,
        declared_rpm_sum=1200.5,
        declared_rpm_count=2,
    )
    back = pickle.loads(pickle.dumps(odd))
    _assert_identical(back, odd)
    assert np.signbit(back.sample_azimuth_deg[1])
    _assert_identical(pickle.loads(pickle.dumps(replace(odd, model="x"))), replace(odd, model="x"))
