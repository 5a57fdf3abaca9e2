"""Hesai decode/encode on the real recordings (tier4/nebula test resources) and round trips.

The `.db3` files are read with sqlite3 directly: table `messages`, column `data` holds one
CDR-serialized `pandar_msgs/msg/PandarScan` per row.
"""

from __future__ import annotations

import itertools
import sqlite3
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from syncaudit.errors import DecodeError
from syncaudit.lidar.hesai import (
    HESAI_LAYOUTS,
    RosHeader,
    decode_hesai,
    detect_hesai_model,
    hesai_returns,
    nebula_packets,
    pandar_scan_packets,
    ros_header,
    stack_packets,
)
from syncaudit.lidar.hesai_encode import (
    build_nebula_packets,
    build_pandar_scan,
    encode_hesai,
    hesai_revolution_schedule,
)

NS = 1_000_000_000


@dataclass(frozen=True)
class Expected:
    """What each real recording holds, measured once and asserted."""

    folder: str
    model: str
    packets_per_scan: tuple[int, ...]
    clock_offset_s: float
    """Driver stamp minus sensor time: the sensor clock is years behind the host."""
    sensor_year: int
    pcd_revolution: int
    """Which zero-to-zero revolution (0-based) the folder's .pcd holds."""
    min_range_m: float
    max_range_m: float
    joint_hist_mismatch: float
    """Upper bound of the azimuth x range histogram mismatch, pcd vs decoded returns."""


CASES = [
    Expected(
        "hesai_40p", "Pandar40P", (360, 359, 360, 360), 168_685_362.4296, 2017, 1, 0.3, 200.0, 0.2
    ),
    Expected(
        "hesai_xt32",
        "PandarXT32",
        (500, 500, 500, 500),
        109_375_908.0812,
        2019,
        2,
        0.05,
        120.0,
        0.03,
    ),
]


def _scans(folder: Path) -> list[bytes]:
    (db,) = sorted(folder.glob("*/*.db3"))
    with sqlite3.connect(db) as con:
        rows = con.execute("SELECT data FROM messages ORDER BY timestamp").fetchall()
    return [bytes(r[0]) for r in rows]


def _pcd_xyz(path: Path) -> NDArray[np.float64]:
    """Binary PCD v0.7 with float32 x y z."""
    raw = path.read_bytes()
    end = raw.index(b"DATA binary\n") + len(b"DATA binary\n")
    head = dict(
        line.split(" ", 1) for line in raw[:end].decode().splitlines() if not line.startswith("#")
    )
    assert head["FIELDS"] == "x y z" and head["SIZE"] == "4 4 4" and head["TYPE"] == "F F F"
    pts = np.frombuffer(raw, "<f4", offset=end).reshape(-1, 3).astype(np.float64)
    assert pts.shape[0] == int(head["POINTS"])
    return pts


@pytest.fixture(scope="module", params=CASES, ids=[c.folder for c in CASES])
def case(request: pytest.FixtureRequest, lidar_data: Path) -> tuple[Expected, list[bytes]]:
    exp: Expected = request.param
    return exp, _scans(lidar_data / exp.folder)


def test_real_scans_decode(case: tuple[Expected, list[bytes]]) -> None:
    exp, scans = case
    counts = []
    times, azimuths, offsets = [], [], []
    for raw in scans:
        stamp_ns, data, size = pandar_scan_packets(raw, "cdr")
        assert np.shares_memory(data, np.frombuffer(raw, np.uint8))  # a view, not a copy
        timing = decode_hesai(data, size, stamp_ns)
        assert timing.vendor == "hesai" and timing.model == exp.model
        assert (timing.return_mode == 0x39).all() and timing.dual_return.all()
        # Dual return: the two blocks of one firing share azimuth and time.
        assert (timing.block_azimuth_deg[:, ::2] == timing.block_azimuth_deg[:, 1::2]).all()
        assert (timing.block_time_ns[:, ::2] == timing.block_time_ns[:, 1::2]).all()
        flat_t = timing.block_time_ns.ravel()
        assert (np.diff(flat_t) >= 0).all()  # block times never go back, across packets too
        # The manual's block timing puts the next packet's first firing one round period
        # after this packet's last (55.56 us Pandar40P, 50 us XT): measured here, not assumed.
        firing_ns = timing.block_time_ns[:, ::2]
        period_ns = HESAI_LAYOUTS[exp.model].round_period_ns
        assert (np.diff(firing_ns, axis=1) == period_ns).all()
        assert abs(np.mean(firing_ns[1:, 0] - firing_ns[:-1, -1]) - period_ns) < 50.0
        counts.append(timing.n_packets)
        times.append(flat_t)
        azimuths.append(timing.block_azimuth_deg.ravel())
        offsets.append(stamp_ns - timing.sensor_time_ns)
        year = np.datetime64(int(timing.sensor_time_ns[0]), "ns").astype("datetime64[Y]")
        assert int(year.astype(int)) + 1970 == exp.sensor_year
        assert build_pandar_scan(ros_header(raw), stamp_ns, data, size) == raw

    # Packets per scan: one turn of firings at 600 rpm over the firings per packet
    # (Pandar40P dual: 1800 firings / 5 = 360; XT32 dual: 2000 / 4 = 500).
    per_turn = hesai_revolution_schedule(exp.model, 600.0, 0, return_mode=0x39).packet_time_ns.size
    assert tuple(counts) == exp.packets_per_scan
    assert max(counts) == per_turn

    # RPM from the azimuth trajectory against sensor time (all four scans).
    t_s = (np.concatenate(times) - times[0][0]) / NS
    az_deg = np.rad2deg(np.unwrap(np.deg2rad(np.concatenate(azimuths))))
    slope_deg_per_s = np.polyfit(t_s, az_deg, 1)[0]
    assert slope_deg_per_s / 6.0 == pytest.approx(600.0, abs=2.0)

    # Sensor clock vs driver stamps: a constant offset of years, jitter below 2 ms.
    off = np.concatenate(offsets)
    assert np.median(off) / NS == pytest.approx(exp.clock_offset_s, abs=0.01)
    assert (off.max() - off.min()) / 1e6 < 2.0


def _revolutions(
    scans: list[bytes],
) -> list[tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.uint8]]]:
    """Zero-to-zero revolutions of the recording: per firing, azimuth and both returns."""
    az, dist, refl = [], [], []
    for raw in scans:
        stamp_ns, data, size = pandar_scan_packets(raw)
        timing = decode_hesai(data, size, stamp_ns)
        d, r = hesai_returns(data, size)
        az.append(timing.block_azimuth_deg[:, ::2].ravel())
        dist.append(d.reshape(-1, 2, d.shape[-1]))
        refl.append(r.reshape(-1, 2, r.shape[-1]))
    a, d, r = np.concatenate(az), np.concatenate(dist), np.concatenate(refl)
    cuts = np.flatnonzero(np.diff(a) < -180.0) + 1
    return [(a[s:e], d[s:e], r[s:e]) for s, e in itertools.pairwise(cuts.tolist())]


def _points(
    rev: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.uint8]], exp: Expected
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(azimuth, range) of the returns a decoder keeps: in range, identical duals once."""
    az, d, r = rev
    ok = (d >= exp.min_range_m) & (d <= exp.max_range_m)
    keep_first = ok[:, 0] & ~((d[:, 0] == d[:, 1]) & (r[:, 0] == r[:, 1]))
    az2 = np.broadcast_to(az[:, None], d[:, 0].shape)
    return (
        np.concatenate([az2[keep_first], az2[ok[:, 1]]]),
        np.concatenate([d[:, 0][keep_first], d[:, 1][ok[:, 1]]]),
    )


def test_pcd_lies_in_decoded_revolution(
    case: tuple[Expected, list[bytes]], lidar_data: Path
) -> None:
    exp, scans = case
    (pcd,) = sorted((lidar_data / exp.folder).glob("*.pcd"))
    xyz = _pcd_xyz(pcd)
    rng_m = np.linalg.norm(xyz, axis=1)

    # Which revolution the source decoder wrote: ranges are frame-free, so compare their
    # 4 mm histograms. One revolution matches to a few points, the others miss by ~15 %.
    revs = _revolutions(scans)
    q_pcd = np.bincount(np.rint(rng_m / 0.004).astype(np.int64), minlength=1 << 16)
    mismatch = []
    for rev in revs:
        _, ranges = _points(rev, exp)
        q = np.bincount(np.rint(ranges / 0.004).astype(np.int64), minlength=1 << 16)
        mismatch.append(np.abs(q - q_pcd).sum() / xyz.shape[0])
    best = int(np.argmin(mismatch))
    assert best == exp.pcd_revolution
    assert mismatch[best] < 0.003
    assert min(m for i, m in enumerate(mismatch) if i != best) > 0.1

    # That revolution covers the full circle: blocks every <= 0.25 deg, wrap included.
    az_rev = revs[best][0]
    steps = np.diff(np.concatenate([az_rev, az_rev[:1] + 360.0]))
    assert steps.min() >= 0.0 and steps.max() <= 0.25
    assert az_rev[-1] - az_rev[0] > 359.5

    # nebula's frame: x = r cos(el) sin(az), y = r cos(el) cos(az) -> az = atan2(x, y).
    az_pcd = np.rad2deg(np.arctan2(xyz[:, 0], xyz[:, 1])) % 360.0
    idx = np.searchsorted(az_rev, az_pcd) % az_rev.size
    gap = np.abs((az_pcd - az_rev[idx] + 180.0) % 360.0 - 180.0)
    gap = np.minimum(gap, np.abs((az_pcd - az_rev[idx - 1] + 180.0) % 360.0 - 180.0))
    assert gap.max() <= 0.125  # every point is inside the decoded azimuth span

    # Where the points are agrees with where the decoded returns are (10 deg x 0.5 m cells);
    # the transposed convention atan2(y, x) does not.
    az_dec, r_dec = _points(revs[best], exp)
    bins = [np.arange(0.0, 360.1, 10.0), np.arange(0.0, 20.01, 0.5)]
    h_dec = np.histogram2d(az_dec, r_dec, bins=bins)[0]
    h_pcd = np.histogram2d(az_pcd, rng_m, bins=bins)[0]
    az_wrong = np.rad2deg(np.arctan2(xyz[:, 1], xyz[:, 0])) % 360.0
    h_wrong = np.histogram2d(az_wrong, rng_m, bins=bins)[0]
    assert np.abs(h_dec - h_pcd).sum() / xyz.shape[0] < exp.joint_hist_mismatch
    assert np.abs(h_dec - h_wrong).sum() / xyz.shape[0] > 0.8


START_NS = 1_673_400_149_311_270_952  # the 40P recording's first driver stamp


@pytest.mark.parametrize(
    ("model", "return_mode", "size", "n_packets"),
    [
        ("Pandar40P", 0x37, 1262, 180),
        ("Pandar40P", 0x39, 1262, 360),
        ("Pandar64", 0x38, 1194, 300),
        ("Pandar64", 0x39, 1194, 600),
        ("PandarQT64", 0x37, 1072, 150),
        ("PandarXT16", 0x37, 568, 250),
        ("PandarXT32", 0x37, 1080, 250),
        ("PandarXT32", 0x3B, 1080, 500),
        ("PandarXT32M", 0x37, 820, 334),
        ("PandarXT32M", 0x3C, 820, 667),
        ("PandarXT32M", 0x3D, 820, 1000),
        ("PandarQT128", 0x37, 1095, 450),
        ("PandarQT128", 0x39, 1095, 900),
        ("AT128", 0x37, 1086, 1200),
        ("Pandar128E4X", 0x37, 861, 900),
        ("Pandar128E4X", 0x39, 861, 1800),
    ],
)
def test_encode_decode_round_trip(model: str, return_mode: int, size: int, n_packets: int) -> None:
    rev = hesai_revolution_schedule(
        model, 600.0, START_NS, return_mode=return_mode, start_azimuth_deg=10.0
    )
    assert rev.packet_time_ns.size == n_packets
    assert (rev.packet_time_ns % 1000 == 0).all()
    data, sizes = encode_hesai(model, rev.block_azimuth_deg, rev.packet_time_ns, return_mode)
    assert data.shape == (n_packets, size) and (sizes == size).all()
    assert detect_hesai_model(data, sizes) == model

    timing = decode_hesai(data, sizes, rev.packet_time_ns + 300_000)
    assert timing.model == model
    np.testing.assert_array_equal(timing.sensor_time_ns, rev.packet_time_ns)
    np.testing.assert_array_equal(timing.block_time_ns, rev.block_time_ns)
    np.testing.assert_array_equal(timing.block_azimuth_deg, rev.block_azimuth_deg)
    assert (timing.return_mode == return_mode).all()
    assert timing.dual_return.all() == (return_mode not in (0x33, 0x34, 0x37, 0x38))

    # The schedule is one turn at constant speed: the first block sits at the start
    # azimuth and the azimuth advances 360 deg per 100 ms of block time (600 rpm).
    assert rev.block_azimuth_deg[0, 0] == pytest.approx(10.0, abs=0.02)
    t = (rev.block_time_ns - rev.block_time_ns[0, 0]).ravel() / NS
    unwrapped = np.rad2deg(np.unwrap(np.deg2rad(rev.block_azimuth_deg.ravel())))
    assert np.polyfit(t, unwrapped, 1)[0] == pytest.approx(3600.0, rel=1e-4)
    assert 359.0 < unwrapped[-1] - unwrapped[0] < 361.0


@pytest.mark.parametrize("model", sorted(HESAI_LAYOUTS))
def test_distances_round_trip(model: str) -> None:
    layout = HESAI_LAYOUTS[model]
    n, b, c = 3, layout.n_blocks, layout.n_channels
    rng = np.random.default_rng(7)
    dist_m = (rng.integers(0, 40_000, (n, b, c)) * 0.004).astype(np.float64)
    refl = rng.integers(0, 256, (n, b, c), dtype=np.uint8)
    az = np.tile(np.arange(b, dtype=np.float64) * 0.25, (n, 1))
    t_ns = START_NS // 1000 * 1000 + np.arange(n, dtype=np.int64) * 1_000_000
    data, size = encode_hesai(model, az, t_ns, 0x37, distance_m=dist_m, reflectivity=refl)
    got_m, got_refl = hesai_returns(data, size)
    np.testing.assert_allclose(got_m, dist_m, atol=1e-9)
    np.testing.assert_array_equal(got_refl, refl)
    # Random returns from a seeded generator are deterministic and plausible.
    d1, _ = encode_hesai(model, az, t_ns, 0x37, rng=np.random.default_rng(1))
    d2, _ = encode_hesai(model, az, t_ns, 0x37, rng=np.random.default_rng(1))
    np.testing.assert_array_equal(d1, d2)
    rand_m, _ = hesai_returns(d1, size)
    assert rand_m.max() <= 100.0 and (rand_m == 0).any()


def test_pandar_and_nebula_messages_round_trip() -> None:
    rev = hesai_revolution_schedule("PandarXT32", 600.0, START_NS)
    data, size = encode_hesai("PandarXT32", rev.block_azimuth_deg, rev.packet_time_ns)
    stamps = rev.packet_time_ns + 250_000
    header = RosHeader(START_NS, "hesai_top", seq=7)
    for encoding in ("cdr", "ros1"):
        raw = build_pandar_scan(header, stamps, data, size, encoding)
        got_stamps, got_data, got_size = pandar_scan_packets(raw, encoding)
        np.testing.assert_array_equal(got_stamps, stamps)
        np.testing.assert_array_equal(got_data[:, : data.shape[1]], data)
        assert (got_data[:, data.shape[1] :] == 0).all()
        np.testing.assert_array_equal(got_size, size)
        assert ros_header(raw, encoding) == (
            header if encoding == "ros1" else header._replace(seq=0)
        )
        assert (
            build_pandar_scan(ros_header(raw, encoding), got_stamps, got_data, got_size, encoding)
            == raw
        )

        # Uniform sizes come back as one zero-copy (n, L) view ...
        neb = build_nebula_packets(header, stamps, data, encoding)
        neb_stamps, packets = nebula_packets(neb, encoding)
        assert isinstance(packets, np.ndarray) and packets.shape == data.shape
        assert np.shares_memory(packets, np.frombuffer(neb, np.uint8))
        np.testing.assert_array_equal(packets, data)
        np.testing.assert_array_equal(neb_stamps, stamps)
        assert build_nebula_packets(ros_header(neb, encoding), neb_stamps, packets, encoding) == neb

        # ... mixed sizes as a list, which stack_packets pads for the decoder.
        mixed = [data[0], data[1, :1077], data[2]]
        neb = build_nebula_packets(header, stamps[:3], mixed, encoding)
        neb_stamps, packets = nebula_packets(neb, encoding)
        assert isinstance(packets, list) and [p.size for p in packets] == [1080, 1077, 1080]
        assert build_nebula_packets(ros_header(neb, encoding), neb_stamps, packets, encoding) == neb
        stacked, stacked_size = stack_packets(packets)
        assert stacked.shape == (3, 1080) and stacked_size.tolist() == [1080, 1077, 1080]
        # 1077 bytes still hold the whole tail (the UDP sequence is cut), so it decodes.
        assert decode_hesai(stacked, stacked_size, neb_stamps).n_packets == 3


def test_unset_date_takes_second_from_host() -> None:
    """AT128 writes Unix seconds; zero means the sensor has no time: take the host second."""
    az = np.zeros((2, 2))
    data, size = encode_hesai("AT128", az, np.array([123_456_000, 987_654_000]), 0x37)
    host_ns = np.array([1_673_400_149_123_900_000, 1_673_400_149_987_999_000])
    timing = decode_hesai(data, size, host_ns)
    np.testing.assert_array_equal(
        timing.sensor_time_ns, [1_673_400_149_123_456_000, 1_673_400_149_987_654_000]
    )


def _one_line(exc: pytest.ExceptionInfo[DecodeError]) -> str:
    msg = str(exc.value)
    assert msg and "\n" not in msg
    return msg


def test_malformed_messages_raise(lidar_data: Path) -> None:
    raw = _scans(lidar_data / "hesai_xt32")[0]
    with pytest.raises(DecodeError) as e:
        pandar_scan_packets(raw[:-100])
    assert "truncated" in _one_line(e) or "declares" in _one_line(e)
    with pytest.raises(DecodeError) as e:
        pandar_scan_packets(raw + b"\0" * 8)
    assert "trailing" in _one_line(e)
    with pytest.raises(DecodeError) as e:
        pandar_scan_packets(b"\x00\x03" + raw[2:])
    assert "encapsulation" in _one_line(e)
    with pytest.raises(DecodeError):
        pandar_scan_packets(raw[:10])
    bad = bytearray(raw)
    bad[28 + 1508 : 28 + 1512] = (1501).to_bytes(4, "little")  # first PandarPacket.size
    with pytest.raises(DecodeError) as e:
        pandar_scan_packets(bytes(bad))
    assert "1500" in _one_line(e)
    neb = build_nebula_packets(RosHeader(0, "x"), np.zeros(2, np.int64), [np.ones(5, np.uint8)] * 2)
    with pytest.raises(DecodeError):
        nebula_packets(neb[:-3])


def _xt32_packets() -> tuple[NDArray[np.uint8], NDArray[np.uint32], NDArray[np.int64]]:
    rev = hesai_revolution_schedule("PandarXT32", 600.0, START_NS)
    data, size = encode_hesai("PandarXT32", rev.block_azimuth_deg[:4], rev.packet_time_ns[:4])
    return data, size, rev.packet_time_ns[:4]


Corruption = Callable[[NDArray[np.uint8], NDArray[np.uint32]], object]


@pytest.mark.parametrize(
    ("corrupt", "message"),
    [
        (lambda d, s: d.__setitem__((1, 0), 0x12), "no known Hesai model"),
        (lambda d, s: d.__setitem__((slice(None), 3), 9), "no known Hesai model"),
        (lambda d, s: d.__setitem__((slice(None), 6), 64), "no known Hesai model"),
        (lambda d, s: d.__setitem__((2, 12 + 130 + 1), 0x8D), "past 360"),
        (lambda d, s: d.__setitem__((0, 1052 + 14), 13), "invalid date-time"),
        (
            lambda d, s: d.__setitem__((0, slice(1052 + 19, 1052 + 23)), [0x41, 0x42, 0x0F, 0]),
            "past 1 s",
        ),
        (lambda d, s: d.__setitem__((slice(None), 1052 + 10), 0x3D), "cannot group 8 blocks"),
        (lambda d, s: d.__setitem__((slice(None), 1052 + 10), 0x39), "not grouped by 2"),
        (lambda d, s: s.__setitem__(1, 1060), "needs"),
    ],
)
def test_malformed_packets_raise(corrupt: Corruption, message: str) -> None:
    data, size, t_ns = _xt32_packets()
    data, size = data.copy(), size.copy()
    corrupt(data, size)
    with pytest.raises(DecodeError) as e:
        decode_hesai(data, size, t_ns)
    assert message in _one_line(e)


def test_other_decode_errors() -> None:
    data, size, t_ns = _xt32_packets()
    p40 = encode_hesai("Pandar40P", np.zeros((4, 10)), t_ns)
    mixed = np.zeros((8, 1262), np.uint8)
    mixed[:4, :1080], mixed[4:] = data, p40[0]
    with pytest.raises(DecodeError) as e:
        decode_hesai(mixed, np.concatenate([size, p40[1]]), np.concatenate([t_ns, t_ns]))
    assert "more than one Hesai model" in _one_line(e)
    broken = p40[0].copy()
    broken[0, 124] = 0x00  # second block's 0xFFEE flag
    with pytest.raises(DecodeError) as e:
        decode_hesai(broken, p40[1], t_ns)
    assert "0xFFEE" in _one_line(e)
    with pytest.raises(DecodeError):
        decode_hesai(data[:0], size[:0], t_ns[:0])
    with pytest.raises(DecodeError):
        decode_hesai(data, size[:2], t_ns)
    with pytest.raises(DecodeError) as e:
        encode_hesai("Pandar128E3X", np.zeros((1, 2)), t_ns[:1])
    assert "unknown Hesai model" in _one_line(e)
    with pytest.raises(ValueError):
        encode_hesai("Pandar40P", np.zeros((1, 10)), t_ns[:1], 0x3D)
    with pytest.raises(ValueError):
        hesai_revolution_schedule("PandarXT32", 600.0, 0, return_mode=0x00)


def test_header_damage_and_text_as_the_wire_readers_say() -> None:
    """The header is read by syncaudit.logs.wire: a frame_id with a flipped bit decodes with
    U+FFFD (it used to raise "not UTF-8": neither format requires valid text), a CDR
    frame_id whose length misses its NUL and PL_CDR (00 03) are refused."""
    rev = hesai_revolution_schedule("PandarXT32", 600.0, START_NS)
    data, size = encode_hesai("PandarXT32", rev.block_azimuth_deg[:2], rev.packet_time_ns[:2])
    for encoding in ("cdr", "ros1"):
        raw = bytearray(
            build_pandar_scan(
                RosHeader(START_NS, "hesai"), rev.packet_time_ns[:2], data, size, encoding
            )
        )
        at = 16  # frame_id text: CDR 4 + stamp 8 + length 4; ROS 1 seq 4 + stamp 8 + length 4
        raw[at] = 0xFF
        assert ros_header(bytes(raw), encoding).frame_id == "\ufffdesai"
        assert (
            pandar_scan_packets(bytes(raw), encoding)[0].tolist() == rev.packet_time_ns[:2].tolist()
        )
    raw = bytearray(
        build_pandar_scan(RosHeader(START_NS, "hesai"), rev.packet_time_ns[:2], data, size)
    )
    raw[16 + 5] = ord("x")  # the NUL of "hesai"
    with pytest.raises(DecodeError, match="has no NUL") as e:
        ros_header(bytes(raw))
    _one_line(e)
    with pytest.raises(DecodeError, match="encapsulation 0003"):
        ros_header(b"\x00\x03" + bytes(raw[2:]))
