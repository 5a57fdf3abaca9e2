"""Cloud timing: each driver convention, layouts (organized, padded, big-endian, ROS 1),
invalid points, stamp conventions, and the real nebula cloud whose times restart per packet."""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray

from syncaudit.errors import DecodeError
from syncaudit.lidar.cloud_layout import cloud_layout
from syncaudit.lidar.cloud_samples import CloudSettings, cloud_samples
from syncaudit.logs import RawMessage
from syncaudit.simulate.cloud_writer import (
    CLOUD_CONVENTIONS,
    CloudConvention,
    CloudPoints,
    cloud_message,
)
from syncaudit.writers.log_writer import LogWriter, open_writer

T0_NS = 1_700_000_000_000_000_000
RPM = 600.0
RATE_DEG_NS = RPM * 6.0 / 1e9
PCD = Path("velodyne_vlp16") / "1673400472138016708.pcd"


@pytest.fixture(params=["mcap", "bag"])
def writer(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[LogWriter]:
    with open_writer(tmp_path / f"w.{request.param}", request.param) as w:
        yield w


def _points(n_blocks: int = 600, beams: int = 16, start_deg: float = 10.0) -> CloudPoints:
    """A revolution's worth of beams firing 2.304 us apart, 55.296 us between blocks."""
    block = T0_NS + 55_296 * np.arange(n_blocks, dtype=np.int64)
    times = block[None, :] + 2_304 * np.arange(beams, dtype=np.int64)[:, None]
    azimuth = np.asarray((start_deg + RATE_DEG_NS * (times - T0_NS)) % 360.0, np.float64)
    return CloudPoints(times, azimuth)


def _raw(writer: LogWriter, msg: object, log_ns: int = T0_NS + 40_000_000) -> RawMessage:
    return RawMessage(
        "/points", "sensor_msgs/msg/PointCloud2", log_ns, writer.serialize(msg), writer.encoding
    )


def _expected_azimuth(time_ns: np.ndarray) -> np.ndarray:
    return (10.0 + RATE_DEG_NS * (time_ns - T0_NS).astype(np.float64)) % 360.0


@pytest.mark.parametrize("convention", CLOUD_CONVENTIONS)
@pytest.mark.parametrize("bigendian", [False, True])
def test_each_convention_gives_the_firing_times_and_azimuths(
    writer: LogWriter, convention: CloudConvention, bigendian: bool
) -> None:
    points = _points()
    stamp = "last" if convention == "velodyne" else "first"
    _, msg = cloud_message(
        writer,
        convention,
        points,
        "lidar",
        0.0,
        stamp=stamp,  # type: ignore[arg-type]
        bigendian=bigendian,
    )
    cloud = cloud_samples(_raw(writer, msg), CloudSettings())
    assert cloud is not None
    assert cloud.points == points.time_ns.size
    assert cloud.first_ns == pytest.approx(int(points.time_ns.min()), abs=300)
    assert cloud.last_ns == pytest.approx(int(points.time_ns.max()), abs=300)
    s = cloud.samples
    assert np.all(np.diff(s.sample_time_ns) > 0)
    # Each sample lies on the rotation: azimuth at its time within 0.001 deg (0.3 us).
    error = (s.sample_azimuth_deg - _expected_azimuth(s.sample_time_ns) + 180) % 360 - 180
    assert np.abs(error).max() < 1e-3
    # Sectors are 1 ms of the epoch's grid: a regular cadence.
    assert set(np.diff(s.sensor_time_ns).tolist()) == {1_000_000}


def test_nan_and_zero_points_are_skipped(writer: LogWriter) -> None:
    points = _points()
    _, msg = cloud_message(writer, "livox", points, "lidar", 0.0)
    data = bytearray(writer.serialize(msg))
    raw = RawMessage("/points", "sensor_msgs/msg/PointCloud2", T0_NS, bytes(data), writer.encoding)
    layout = cloud_layout(raw)
    grid = np.frombuffer(data, np.uint8, layout.data_size, layout.data_offset)
    xy = np.ndarray((layout.n_points, 2), "<f4", grid, 0, (layout.point_step, 4))
    xy.setflags(write=True)
    xy[::3] = np.nan
    xy[1::3] = 0.0
    cloud = cloud_samples(
        RawMessage("/p", raw.msgtype, T0_NS, bytes(data), raw.encoding), CloudSettings()
    )
    assert cloud is not None
    assert cloud.points == layout.n_points - len(range(0, layout.n_points, 3)) - len(
        range(1, layout.n_points, 3)
    )
    s = cloud.samples
    error = (s.sample_azimuth_deg - _expected_azimuth(s.sample_time_ns) + 180) % 360 - 180
    assert np.abs(error).max() < 1e-3


def test_stamp_marks_last_shifts_times_that_count_from_the_first_point(writer: LogWriter) -> None:
    points = _points()
    stamp_ns, _ = cloud_message(writer, "ouster", points, "lidar", 0.0, stamp="last")
    # Written with relative times >= 0 counted from the stamp (the last point): the rig
    # says the stamp is the last point, so the times end there.
    _, first_msg = cloud_message(writer, "ouster", points, "lidar", 0.0, stamp="first")
    raw = _raw(writer, first_msg)
    as_first = cloud_samples(raw, CloudSettings())
    as_last = cloud_samples(raw, CloudSettings(stamp_marks="last"))
    assert as_first is not None and as_last is not None
    assert as_first.first_ns == int(points.time_ns.min())
    assert as_last.last_ns == as_first.stamp_ns
    assert stamp_ns == int(points.time_ns.max())


def test_azimuth_from_xy_uses_the_x_axis_azimuth(writer: LogWriter) -> None:
    points = _points()
    _, msg = cloud_message(writer, "livox", points, "lidar", 90.0)  # Hesai: +X at 90 deg
    cloud = cloud_samples(_raw(writer, msg), CloudSettings(x_axis_azimuth_deg=90.0))
    assert cloud is not None
    s = cloud.samples
    error = (s.sample_azimuth_deg - _expected_azimuth(s.sample_time_ns) + 180) % 360 - 180
    assert np.abs(error).max() < 1e-3


def test_a_cloud_without_time_field_is_one_line_error(writer: LogWriter) -> None:
    _, msg = cloud_message(writer, "livox", _points(), "lidar", 0.0)
    with pytest.raises(DecodeError, match="no per-point time field"):
        cloud_samples(_raw(writer, msg), CloudSettings(time_field="stamp"))


def _pcd_cloud(writer: LogWriter, path: Path) -> RawMessage:
    """The .pcd's points as a PointCloud2 (fields, offsets and bytes as in the file)."""
    raw = path.read_bytes()
    head, _, body = raw.partition(b"DATA binary\n")
    meta = {
        line.split()[0]: line.split()[1:]
        for line in head.decode().splitlines()
        if line and not line.startswith("#")
    }
    codes = {("F", "4"): 7, ("F", "8"): 8, ("U", "1"): 2, ("U", "2"): 4, ("U", "4"): 6}
    fields, offset = [], 0
    for name, size, kind in zip(meta["FIELDS"], meta["SIZE"], meta["TYPE"], strict=True):
        fields.append(
            writer.new_msg(
                "sensor_msgs/msg/PointField",
                name=name,
                offset=offset,
                datatype=codes[(kind, size)],
                count=1,
            )
        )
        offset += int(size)
    n = int(meta["POINTS"][0])
    msg = writer.new_msg(
        "sensor_msgs/msg/PointCloud2",
        header=writer.header(1_673_400_472_138_016_708, "lidar"),
        height=1,
        width=n,
        fields=fields,
        is_bigendian=False,
        point_step=offset,
        row_step=offset * n,
        data=np.frombuffer(body[: offset * n], np.uint8),
        is_dense=True,
    )
    return _raw(writer, msg, 1_673_400_472_138_016_708)


def test_real_nebula_cloud_with_per_packet_times_is_refused(
    writer: LogWriter, lidar_data: Path
) -> None:
    raw = _pcd_cloud(writer, lidar_data / PCD)
    with pytest.raises(DecodeError, match=r"restarts 149 times .* relative to each packet"):
        cloud_samples(raw, CloudSettings())


def test_real_nebula_azimuth_is_clockwise_from_x(writer: LogWriter, lidar_data: Path) -> None:
    """The file's azimuth field equals atan2(-y, x): what the x/y path computes."""
    from syncaudit.lidar.cloud_fields import measured_x_axis_deg, point_azimuth_deg

    raw = _pcd_cloud(writer, lidar_data / PCD)
    layout = cloud_layout(raw)
    with_field = point_azimuth_deg(layout, raw.data, 0.0)
    fields = {k: v for k, v in layout.fields.items() if k != "azimuth"}
    from_xy = point_azimuth_deg(
        type(layout)(**{**{s: getattr(layout, s) for s in layout.__slots__}, "fields": fields}),
        raw.data,
        0.0,
    )
    ok = np.isfinite(from_xy)
    error = (with_field[ok] - from_xy[ok] + 180) % 360 - 180
    assert ok.sum() > 14_000
    assert np.abs(error).max() < 0.05
    assert measured_x_axis_deg(layout, raw.data) == 0.0  # what the rig guess measures


@pytest.mark.parametrize("cut_blocks", [None, 77, 450])
def test_where_clouds_are_cut_does_not_move_the_crossings(
    writer: LogWriter, cut_blocks: int | None
) -> None:
    """Per revolution (None: at the zero azimuth), per packet batch (77 blocks) or at a
    custom angle (450 blocks = 180 deg past the start): the same zero crossings."""
    from syncaudit.lidar.cloud_scan import CloudFeeder
    from syncaudit.lidar.scan import LidarScanner

    n_blocks = 5400  # three revolutions at 600 rpm, 55.296 us a block
    points = _points(n_blocks)
    per_turn = round(360.0 / (RATE_DEG_NS * 55_296))
    first = round((360.0 - 10.0) / (RATE_DEG_NS * 55_296))  # the head reaches 0 deg there
    if cut_blocks is None:
        cuts = list(range(first, n_blocks, per_turn))
    else:
        cuts = list(range(cut_blocks, n_blocks, cut_blocks))
    bounds = [0, *cuts, n_blocks]
    feeder = CloudFeeder(LidarScanner.create("/points", zero_azimuth_deg=0.0), CloudSettings())
    for lo, hi in itertools.pairwise(bounds):
        part = CloudPoints(points.time_ns[:, lo:hi], points.azimuth_deg[:, lo:hi])
        _, msg = cloud_message(writer, "nebula", part, "lidar", 0.0)
        log_ns = int(part.time_ns.max()) + 300_000
        cloud = cloud_samples(_raw(writer, msg, log_ns), CloudSettings())
        assert cloud is not None
        feeder.feed(cloud)
    zeros = feeder.finish().revolutions.zero_crossing_sensor_ns
    exact = T0_NS + np.rint((360.0 * np.arange(1, 4) - 10.0) / RATE_DEG_NS).astype(np.int64)
    assert zeros.size == 3
    assert np.abs(zeros - exact).max() < 200  # ns


def _stream(
    writer: LogWriter, shift_ns: int, settings: CloudSettings
) -> tuple[list[str], NDArray[np.int64]]:
    """Three revolutions as clouds cut every 1800 blocks (~one turn), logged 300 us after
    their last beam; each cloud's points are written `shift_ns` later than they fired."""
    from syncaudit.lidar.cloud_scan import CloudFeeder
    from syncaudit.lidar.scan import LidarScanner

    points = _points(5400)
    feeder = CloudFeeder(LidarScanner.create("/points"), settings)
    for lo in range(0, 5400, 1800):
        part = CloudPoints(
            points.time_ns[:, lo : lo + 1800] + shift_ns, points.azimuth_deg[:, lo : lo + 1800]
        )
        _, msg = cloud_message(writer, "ouster", part, "lidar", 0.0)
        log_ns = int(points.time_ns[:, lo : lo + 1800].max()) + 300_000
        cloud = cloud_samples(_raw(writer, msg, log_ns), settings)
        assert cloud is not None
        feeder.feed(cloud)
    scan = feeder.finish()
    return feeder.notes, scan.revolutions.zero_crossing_sensor_ns


def test_stamps_marking_the_last_point_are_noticed_and_set_right(writer: LogWriter) -> None:
    """A driver stamping each cloud at its last point while its `t` counts from the first:
    read as 'first', every point lands one cloud late, which only the arrival shows."""
    span_ns = int(_points(1800).time_ns.max() - _points(1800).time_ns.min())
    notes, late = _stream(writer, span_ns, CloudSettings())
    (note,) = notes
    assert "set lidar.stamp_marks: last" in note
    notes_ok, right = _stream(writer, span_ns, CloudSettings(stamp_marks="last"))
    assert notes_ok == []
    _, truth = _stream(writer, 0, CloudSettings())
    assert right.size == truth.size and np.abs(right - truth).max() < 200
    assert late.size and np.abs(late[0] - truth[0]) > 1_000_000
