"""The revolution tracker's shortcuts give exactly what its general path gives.

The tracker runs in the audit's parent on every batch of packets, so it skips work where
the answer is known without it: the float remainder of azimuths already in [0, 360), the
sorts of `np.unique` on packet and revolution numbers that are nondecreasing, the median
packet gap when last batch's median is still the middle value, and the median block rate
where no sample's gap-turn correction depends on it. Each test runs the tracker with the
shortcuts and with every one of them replaced by the general computation (the code of
main afb8a17), on real recordings, simulated logs with drops, dual returns and VLS-128
banks, and on hand-made edge cases (out-of-order packets, gaps of many turns, one packet
per chunk, azimuths at -0.0, 360 and NaN), and asserts every output is identical.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from sample_chunks import split_samples
from syncaudit.lidar import revolutions as rv
from syncaudit.lidar.revolutions import RevolutionTracker
from syncaudit.lidar.samples import PacketSamples, concat_samples, packet_samples
from syncaudit.lidar.stream import iter_packet_chunks
from syncaudit.logs import open_log
from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log

Outcome = tuple[dict[str, NDArray[np.generic]], float, object, int]


def _general_gap_turns(
    self: RevolutionTracker,
    wraps: NDArray[np.int64],
    dts: NDArray[np.float64],
    step: NDArray[np.float64],
    moving: NDArray[np.bool_],
    ratios: NDArray[np.float64],
    max_moving_dt: float,
) -> None:
    wraps += rv._gap_turns(self._omega(), dts, step)


def _force_general(m: pytest.MonkeyPatch) -> None:
    """Every shortcut of the tracker replaced by the general computation."""
    m.setattr(rv, "_orient", lambda az, direction: (direction * az) % rv.FULL_TURN_DEG)
    m.setattr(rv, "run_starts", lambda values: None)
    m.setattr(rv, "_median_int", lambda values, guess: float(np.median(values)))
    m.setattr(RevolutionTracker, "_add_gap_turns", _general_gap_turns)


def _outcome(chunks: list[PacketSamples], **options: object) -> Outcome:
    tracker = RevolutionTracker(**options)  # type: ignore[arg-type]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # NaN azimuths in the edge cases
        for chunk in chunks:
            tracker.feed(chunk)
        columns = tracker.finish()
    arrays = {name: getattr(columns, name) for name in columns.__dataclass_fields__}
    return arrays, tracker.omega_blocks_deg_s, tracker.cropped_sector(), tracker.outlier_blocks


def _assert_same(fast: Outcome, slow: Outcome) -> None:
    assert fast[0].keys() == slow[0].keys()
    for name, values in fast[0].items():
        np.testing.assert_array_equal(values, slow[0][name], err_msg=name, strict=True)
    assert (fast[1] == slow[1]) or (math.isnan(fast[1]) and math.isnan(slow[1]))
    assert fast[2:] == slow[2:]


OPTIONS: list[dict[str, object]] = [
    {"zero_azimuth_deg": 0.0, "target_azimuth_deg": (0.0, 60.0, 120.0, 180.0, 240.0, 300.0)},
    {"zero_azimuth_deg": 123.45, "target_azimuth_deg": (10.0, 359.99)},
    {"zero_azimuth_deg": 359.99, "direction": -1, "target_azimuth_deg": (90.0,)},
]


def _compare(
    chunks: list[PacketSamples], monkeypatch: pytest.MonkeyPatch, *, expect_revolutions: bool
) -> None:
    """Fast and general path agree for every option set; the fast one found revolutions."""
    fast = [_outcome(chunks, **o) for o in OPTIONS]
    if expect_revolutions:
        assert fast[0][0]["zero_crossing_sensor_ns"].size >= 2
    with monkeypatch.context() as m:
        _force_general(m)
        slow = [_outcome(chunks, **o) for o in OPTIONS]
    for f, s in zip(fast, slow, strict=True):
        _assert_same(f, s)


def _per_scan(path: Path, topic: str | None = None) -> list[PacketSamples]:
    with open_log(path) as log:
        if topic is None:
            topic = next(
                t.name
                for t in log.topics.values()
                if t.msgtype.startswith(("velodyne", "pandar", "hesai"))
            )
        return [packet_samples(c.timing, c.driver_stamp_ns) for c in iter_packet_chunks(log, topic)]


def _without_packets(samples: PacketSamples, drop: NDArray[np.bool_]) -> PacketSamples:
    """The chunk without the packets marked in `drop` (gaps in the cadence)."""
    keep = ~drop
    new_index = np.cumsum(keep) - 1
    kept_samples = keep[samples.sample_packet]
    return replace(
        samples,
        sensor_time_ns=samples.sensor_time_ns[keep],
        driver_stamp_ns=samples.driver_stamp_ns[keep],
        sample_time_ns=samples.sample_time_ns[kept_samples],
        sample_azimuth_deg=samples.sample_azimuth_deg[kept_samples],
        sample_packet=new_index[samples.sample_packet[kept_samples]],
    )


REAL = [
    ("velodyne_vlp16", "1673400471837873222", "/velodyne_packets"),
    ("velodyne_vlp32", "1713492677464078412", "/sensing/lidar/front/velodyne_packets"),
    ("hesai_40p", "1673400149412331409", "/pandar_packets"),
    ("hesai_xt32", "1673400677802009732", "/pandar_packets"),
]


@pytest.mark.parametrize(("folder", "bag", "topic"), REAL)
def test_real_recordings(
    lidar_data: Path, folder: str, bag: str, topic: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    per_scan = _per_scan(lidar_data / folder / bag, topic)
    _compare(per_scan, monkeypatch, expect_revolutions=True)
    whole = concat_samples(per_scan)
    _compare([whole], monkeypatch, expect_revolutions=True)
    # One packet per chunk: every batch-level shortcut on its smallest input.
    singles, rest = [], whole
    for _ in range(whole.n_packets - 1):
        head, rest = split_samples(rest, 1)
        singles.append(head)
    singles.append(rest)
    _compare(singles, monkeypatch, expect_revolutions=True)


@pytest.mark.parametrize(("folder", "bag", "topic"), REAL[:1] + REAL[2:3])
def test_real_recordings_with_gaps(
    lidar_data: Path, folder: str, bag: str, topic: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Lost packets: single ones, runs of a sector, and most of a turn."""
    whole = concat_samples(_per_scan(lidar_data / folder / bag, topic))
    rng = np.random.default_rng(3)
    drop = rng.random(whole.n_packets) < 0.02
    n = whole.n_packets
    drop[n // 5 : n // 5 + 7] = True
    drop[n // 2 : n // 2 + n // 6] = True
    gappy = _without_packets(whole, drop)
    _compare([gappy], monkeypatch, expect_revolutions=True)
    pieces, rest, done = [], gappy, 0
    for cut in np.sort(rng.choice(np.arange(1, gappy.n_packets), 12, replace=False)).tolist():
        head, rest = split_samples(rest, cut - done)
        pieces.append(head)
        done = cut
    _compare([*pieces, rest], monkeypatch, expect_revolutions=True)


@pytest.mark.parametrize(
    ("model", "drops"), [("VLS-128", 0.01), ("PandarXT32M", 0.03), ("VLP-16", 0.0)]
)
def test_simulated_logs(
    tmp_path: Path, model: str, drops: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    """VLS-128 banks sharing an azimuth, the XT32M's dual returns, drops and none."""
    out = tmp_path / "log.mcap"
    simulate_sync_log(
        out, SyncSimConfig(seed=11, duration_s=1.5, lidar_model=model, packet_drop_fraction=drops)
    )
    per_scan = _per_scan(out)
    if model == "PandarXT32M":
        assert any(s.dual_return for s in per_scan)
    _compare(per_scan, monkeypatch, expect_revolutions=True)
    _compare([concat_samples(per_scan)], monkeypatch, expect_revolutions=True)


def _synthetic(
    times_ns: NDArray[np.int64], azimuth_deg: NDArray[np.float64], packet: NDArray[np.int64]
) -> PacketSamples:
    n = int(packet.max()) + 1 if packet.size else 0
    sensor = np.arange(n, dtype=np.int64) * 1_000 + int(times_ns[0] if times_ns.size else 0)
    return PacketSamples(
        vendor="velodyne",
        model="VLP-16",
        sensor_time_ns=sensor,
        driver_stamp_ns=sensor + 300_000,
        sample_time_ns=times_ns,
        sample_azimuth_deg=azimuth_deg,
        sample_packet=packet,
        return_modes=frozenset({0x37}),
        dual_return=False,
        outlier_blocks=0,
    )


def test_hand_made_edge_cases(monkeypatch: pytest.MonkeyPatch) -> None:
    """Out-of-order packets and samples, steps back, -0.0, 360, NaN, jumps of many turns."""
    rng = np.random.default_rng(9)
    n = 3_000
    times = np.cumsum(rng.integers(900, 1_100, n)).astype(np.int64) + 10**18
    azimuth = np.round((times - times[0]) * 0.0036 + rng.normal(0.0, 0.05, n), 2) % 360.0
    packet = np.repeat(np.arange(n // 2, dtype=np.int64), 2)
    base = _synthetic(times, azimuth, packet)
    cases = {"plain": base}
    backwards = packet.copy()
    backwards[100:104] = backwards[100:104][::-1]  # packets out of order
    cases["packets out of order"] = replace(base, sample_packet=backwards)
    stamps = base.sensor_time_ns.copy()
    stamps[[40, 41]] = stamps[[41, 40]]  # sensor stamps out of order, repeated
    stamps[200] = stamps[199]
    cases["stamps out of order"] = replace(base, sensor_time_ns=stamps)
    odd = azimuth.copy()
    odd[[5, 6]] = -0.0
    odd[7] = 360.0
    odd[900] = np.nan
    cases["-0.0, 360 and NaN"] = replace(base, sample_azimuth_deg=odd)
    zeros = azimuth.copy()
    zeros[azimuth < 1.0] = -0.0
    cases["-0.0 only"] = replace(base, sample_azimuth_deg=zeros)
    jumpy_times = times.copy()
    jumpy_times[1_500:] += 2_345_678_901  # a gap of 23.5 turns: corrections at the median
    cases["gap of many turns"] = replace(base, sample_time_ns=jumpy_times)
    still = azimuth.copy()
    still[300:700] = still[300]  # the head stops: no moving sample in a chunk
    cases["head stops"] = replace(base, sample_azimuth_deg=still)
    for name, chunk in cases.items():
        pieces = [chunk]
        for at in (1_400, 700, 300, 1):
            head, rest = split_samples(pieces.pop(), at)
            pieces += [head, rest]
        try:
            _compare([chunk], monkeypatch, expect_revolutions=True)
            _compare(pieces, monkeypatch, expect_revolutions=False)
        except AssertionError as exc:  # pragma: no cover - names the failing case
            raise AssertionError(f"{name}: {exc}") from exc


def test_gap_turns_both_ends_and_median() -> None:
    """_add_gap_turns equals the correction at the median, through each of its branches."""
    rng = np.random.default_rng(4)
    hits = {"bound fails": 0, "ends agree": 0, "ends differ": 0}
    for trial in range(400):
        n = int(rng.integers(1, 60))
        dts = rng.choice([0.0, 1_000.0, -500.0, 1e6, 2.3e8, 5e9], n) + rng.normal(0, 5, n)
        step = rng.choice([0.0, 0.01, 5.0, 89.99, 90.0, 179.99, 180.0, 359.99], n)
        moving = (dts > 0) & (step > 0) & (step < rv.MAX_BLOCK_STEP_DEG)
        if not moving.any():
            continue
        ratios = step[moving] / dts[moving]
        tracker = RevolutionTracker()
        tracker._omega_ratios = ratios
        want = rv._gap_turns(float(np.median(ratios)), dts, step)
        got = np.zeros(n, dtype=np.int64)
        max_dt = float(dts[moving].max())
        lo, hi = float(ratios.min()), float(ratios.max())
        if not hi * max_dt < rv.NO_TURN_BOUND_DEG:
            hits["bound fails"] += 1
        elif (~moving).any():
            o = ~moving
            same = np.array_equal(
                rv._gap_turns(lo, dts[o], step[o]), rv._gap_turns(hi, dts[o], step[o])
            )
            hits["ends agree" if same else "ends differ"] += 1
        tracker._add_gap_turns(got, dts, step, moving, ratios, max_dt)
        np.testing.assert_array_equal(got, want, err_msg=f"trial {trial}")
    assert all(hits.values()), hits


@pytest.mark.parametrize("size", [1, 2, 3, 4, 7, 100, 101, 4096])
def test_median_int_is_np_median(size: int) -> None:
    rng = np.random.default_rng(size)
    for _ in range(50):
        values = rng.choice(
            [159_000, 160_000, 319_000, 1, 2**40], size, p=[0.45, 0.4, 0.1, 0.03, 0.02]
        )
        want = float(np.median(values))
        guesses = [want, math.floor(want), math.ceil(want), want + 1, math.nan, 159_500.5, 0.0]
        for guess in guesses + [float(v) for v in values[:5]]:
            got = rv._median_int(values.astype(np.int64), guess)
            assert got == want, (values, guess)


def test_orient_is_the_remainder_bit_for_bit() -> None:
    values = np.array([0.0, -0.0, 1e-300, 12.34, 359.99, 360.0 - 1e-13, 360.0, -1e-13, np.nan])
    rng = np.random.default_rng(1)
    for _ in range(200):
        az = rng.choice(values, int(rng.integers(1, 6)))
        for direction in (1, -1):
            with np.errstate(invalid="ignore"):
                want = (direction * az) % rv.FULL_TURN_DEG
                got = rv._orient(az, direction)
            np.testing.assert_array_equal(got, want)
            assert np.array_equal(np.signbit(got), np.signbit(want)), (az, direction)
