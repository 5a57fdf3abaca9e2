"""Ouster decoding on the real OS-0-128 512x10 recording (ouster-sdk test bag) and round trips."""

from __future__ import annotations

import dataclasses
import json
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray
from rosbags.rosbag1 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from syncaudit.errors import DecodeError
from syncaudit.lidar.ouster import (
    OusterMetadata,
    build_ouster_packet_msg,
    decode_ouster,
    decode_ouster_columns,
    encode_ouster,
    ouster_clock_is_epoch,
    ouster_packet_bytes,
    parse_ouster_metadata,
)
from syncaudit.lidar.samples import packet_samples
from syncaudit.lidar.scan import LidarScanner

REPO = Path(__file__).resolve().parents[2]
BAG = Path("ouster_os1_512x10") / "512x10_raw.bag"
NOMINAL_COLUMN_NS = 1e9 / 10 / 512  # 512x10: 100 ms per revolution, 512 columns


@dataclasses.dataclass(frozen=True)
class Recording:
    """What the test bag holds, read with rosbags directly."""

    metadata_json: str
    packets: NDArray[np.uint8]
    """(32, 8448) lidar packet payloads."""
    log_time_ns: NDArray[np.int64]
    """(32,) bag receive time of each lidar packet."""
    digest: str
    """md5 of the PacketMsg definition stored in the bag."""


@pytest.fixture(scope="module")
def rec(lidar_data: Path) -> Recording:
    path = lidar_data / BAG
    if not path.is_file():
        pytest.skip(f"{path} is absent")
    bufs: list[NDArray[np.uint8]] = []
    times: list[int] = []
    text = ""
    digest = ""
    with Reader(path) as reader:
        for conn, log_time, raw in reader.messages():
            if conn.topic == "/os_node0/lidar_packets":
                bufs.append(ouster_packet_bytes(raw, "ros1"))
                times.append(log_time)
                digest = conn.digest
            elif conn.topic == "/os_node0/metadata":
                (length,) = struct.unpack_from("<I", raw)  # std_msgs/String, ROS 1
                text = bytes(raw[4 : 4 + length]).decode()
    return Recording(text, np.stack(bufs), np.array(times, dtype=np.int64), digest)


@pytest.fixture(scope="module")
def meta(rec: Recording) -> OusterMetadata:
    return parse_ouster_metadata(rec.metadata_json)


# --------------------------------------------------------------------------- metadata


def test_metadata_of_the_real_sensor(meta: OusterMetadata) -> None:
    assert meta.lidar_mode == "512x10"
    assert (meta.columns_per_frame, meta.columns_per_packet) == (512, 16)
    assert meta.pixels_per_column == 128
    assert meta.column_window == (0, 511)
    assert meta.rotation_rate_hz == 10
    assert meta.rotation_rate_rpm == 600.0
    assert meta.udp_profile_lidar == "RNG15_RFL8_NIR8"
    assert meta.prod_line == "OS-0-128"  # the folder says OS1; the sensor says OS-0
    assert meta.prod_sn == "992108000265"
    assert meta.initialization_id == 9599939
    assert meta.timestamp_mode == "TIME_FROM_INTERNAL_OSC"
    assert meta.firmware_rev == "v2.3.0"
    assert len(meta.beam_azimuth_angles_deg) == 128
    assert meta.beam_azimuth_angles_deg[:2] == (10.84, 3.54)
    assert meta.lidar_origin_to_beam_origin_mm == 27.67
    # 32-byte header + 16 x (12-byte column header + 128 x 4-byte pixels) + 32-byte footer
    assert meta.packet_bytes == 8448


def _to_legacy_flat(nested: dict[str, Any]) -> dict[str, Any]:
    """The flat layout older ouster_ros / SDKs wrote, with the nested file's values."""
    fmt = nested["lidar_data_format"]
    info = nested["sensor_info"]
    beams = nested["beam_intrinsics"]
    return {
        "beam_altitude_angles": beams["beam_altitude_angles"],
        "beam_azimuth_angles": beams["beam_azimuth_angles"],
        "lidar_origin_to_beam_origin_mm": beams["lidar_origin_to_beam_origin_mm"],
        "build_rev": info["build_rev"],
        "data_format": {
            "column_window": fmt["column_window"],
            "columns_per_frame": fmt["columns_per_frame"],
            "columns_per_packet": fmt["columns_per_packet"],
            "pixel_shift_by_row": fmt["pixel_shift_by_row"],
            "pixels_per_column": fmt["pixels_per_column"],
            "udp_profile_imu": "LEGACY",
            "udp_profile_lidar": fmt["udp_profile_lidar"],
        },
        "hostname": "",
        "initialization_id": info["initialization_id"],
        "json_calibration_version": 4,
        "lidar_mode": nested["config_params"]["lidar_mode"],
        "prod_line": info["prod_line"],
        "prod_sn": info["prod_sn"],
        "timestamp_mode": nested["config_params"]["timestamp_mode"],
        "status": "RUNNING",
    }


def test_legacy_flat_metadata_equals_nested(rec: Recording, meta: OusterMetadata) -> None:
    flat = _to_legacy_flat(json.loads(rec.metadata_json))
    assert parse_ouster_metadata(json.dumps(flat)) == meta
    # the same angles nested under beam_intrinsics, as some flat writers do
    beams = {k: flat.pop(k) for k in list(flat) if k.startswith(("beam_", "lidar_origin"))}
    assert parse_ouster_metadata(json.dumps({**flat, "beam_intrinsics": beams})) == meta


def test_firmware_1_12_metadata_without_data_format() -> None:
    text = json.dumps(
        {
            "beam_altitude_angles": [16.5 - 0.5 * i for i in range(64)],
            "beam_azimuth_angles": [3.0, 0.9, -1.2, -3.3] * 16,
            "build_rev": "v1.12.0",
            "lidar_mode": "1024x20",
            "prod_line": "OS-1-64",
            "prod_sn": "991913000010",
        }
    )
    m = parse_ouster_metadata(text)
    assert (m.udp_profile_lidar, m.columns_per_frame, m.columns_per_packet) == ("LEGACY", 1024, 16)
    assert (m.pixels_per_column, m.rotation_rate_hz, m.timestamp_mode) == (64, 20, None)
    assert m.column_window == (0, 1023)
    assert m.packet_bytes == 12608  # the documented OS1-64 legacy packet size
    assert m.column_period_ns == pytest.approx(1e9 / 20 / 1024)


@pytest.mark.parametrize(
    "text",
    [
        "",
        "{not json",
        "[1, 2]",
        '{"hello": 1}',
        '{"lidar_mode": "512x10"}',
        '{"lidar_data_format": 5}',
    ],
)
def test_nonsense_metadata_raises(text: str) -> None:
    with pytest.raises(DecodeError) as info:
        parse_ouster_metadata(text)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("path", "value"),
    [
        (("config_params", "lidar_mode"), "1024x10"),  # disagrees with columns_per_frame
        (("config_params", "lidar_mode"), "fast"),
        (("lidar_data_format", "udp_profile_lidar"), "RNG99"),
        (("lidar_data_format", "pixels_per_column"), "128"),
        (("lidar_data_format", "column_window"), [0, 600]),
        (("beam_intrinsics", "beam_azimuth_angles"), [1.0, 2.0]),
    ],
)
def test_inconsistent_metadata_raises(rec: Recording, path: tuple[str, str], value: Any) -> None:
    doc = json.loads(rec.metadata_json)
    doc[path[0]][path[1]] = value
    with pytest.raises(DecodeError, match="ouster metadata"):
        parse_ouster_metadata(json.dumps(doc))


# --------------------------------------------------------------------------- real packets


def test_bag_definition_matches_schema_files(rec: Recording) -> None:
    for package in ("ouster_ros", "ouster_sensor_msgs"):
        text = (REPO / "schemas" / package / "msg" / "PacketMsg.msg").read_text()
        store = get_typestore(Stores.EMPTY)
        store.register(get_types_from_msg(text, f"{package}/msg/PacketMsg"))
        assert store.generate_msgdef(f"{package}/msg/PacketMsg")[1] == rec.digest


def test_packet_headers_match_metadata(rec: Recording, meta: OusterMetadata) -> None:
    cols = decode_ouster_columns(rec.packets, meta)
    assert rec.packets.shape == (32, 8448)
    assert np.all(cols.packet_type == 1)
    assert np.all(cols.init_id == meta.initialization_id)
    assert np.all(cols.prod_sn == int(meta.prod_sn))
    assert np.all(cols.frame_id == 1798)  # one frame
    assert np.all(cols.valid)
    assert np.all(cols.status == 1)


def test_one_full_frame(rec: Recording, meta: OusterMetadata) -> None:
    timing = decode_ouster(rec.packets, meta)
    cols = decode_ouster_columns(rec.packets, meta)
    assert timing.vendor == "ouster"
    assert timing.model == "OS-0-128"
    assert timing.block_time_ns.shape == (32, 16)
    assert np.all(timing.return_mode == 4)  # RNG15_RFL8_NIR8
    assert not np.any(timing.dual_return)
    # measurement ids 0..511, each once, in packet order
    np.testing.assert_array_equal(cols.measurement_id.ravel(), np.arange(512))
    # column times strictly increasing, about 100 ms / 512 apart
    t = timing.block_time_ns.ravel()
    dt = np.diff(t)
    assert np.all(dt > 0)
    assert dt.mean() == pytest.approx(195115.8, abs=0.1)  # measured; nominal 195312.5
    assert dt.mean() == pytest.approx(NOMINAL_COLUMN_NS, rel=2e-3)
    assert dt.std() == pytest.approx(898.2, abs=0.1)
    assert np.all(np.abs(dt - NOMINAL_COLUMN_NS) < 0.03 * NOMINAL_COLUMN_NS)
    assert t[-1] - t[0] == 99_704_180
    np.testing.assert_array_equal(timing.sensor_time_ns, timing.block_time_ns[:, 0])


def test_rotation_from_azimuth_vs_time(rec: Recording, meta: OusterMetadata) -> None:
    timing = decode_ouster(rec.packets, meta)
    az = timing.block_azimuth_deg.ravel()
    assert np.all((az >= 0.0) & (az < 360.0))
    assert az[0] == 0.0
    assert az[-1] == pytest.approx(360.0 * 511 / 512)  # span covers the whole circle
    np.testing.assert_allclose(np.diff(az), 360.0 / 512)
    t_s = (timing.block_time_ns.ravel() - timing.block_time_ns[0, 0]) * 1e-9
    slope_deg_per_s = np.polyfit(t_s, az, 1)[0]
    rpm = slope_deg_per_s / 6.0
    assert rpm == pytest.approx(600.66, abs=0.01)  # measured in the sensor's own clock
    assert rpm == pytest.approx(meta.rotation_rate_rpm, rel=2e-3)


def test_sensor_clock_counts_from_power_on(rec: Recording, meta: OusterMetadata) -> None:
    timing = decode_ouster(rec.packets, meta)
    assert meta.timestamp_mode == "TIME_FROM_INTERNAL_OSC"
    assert timing.sensor_time_ns[0] == 291_159_252_580  # about 4.9 min after power-on
    assert not ouster_clock_is_epoch(timing.sensor_time_ns)
    assert ouster_clock_is_epoch(rec.log_time_ns)
    # host bag time minus sensor time: a constant ~1723828123.12 s plus latency jitter
    offset_ns = rec.log_time_ns - timing.sensor_time_ns
    assert offset_ns.min() == 1_723_828_123_119_911_651
    assert offset_ns.max() - offset_ns.min() == 461_937  # 0.46 ms spread over 32 packets


def test_reencoding_the_real_frame_gives_its_headers(rec: Recording, meta: OusterMetadata) -> None:
    cols = decode_ouster_columns(rec.packets, meta)
    again = encode_ouster(meta, cols.measurement_id, cols.timestamp_ns, cols.frame_id)
    assert again.shape == rec.packets.shape
    np.testing.assert_array_equal(again[:, :32], rec.packets[:, :32])  # packet header
    starts = 32 + meta.column_bytes * np.arange(16)
    for start in starts:
        np.testing.assert_array_equal(
            again[:, start : start + 12], rec.packets[:, start : start + 12]
        )


# --------------------------------------------------------------------------- round trips


@pytest.mark.parametrize(
    ("profile", "size"),
    [("LEGACY", 24896), ("RNG19_RFL8_SIG16_NIR16", 24832), ("RNG19_RFL8_SIG16_NIR16_DUAL", 33024)],
)
def test_round_trip_profiles(rec: Recording, meta: OusterMetadata, profile: str, size: int) -> None:
    real = decode_ouster_columns(rec.packets, meta)
    other = dataclasses.replace(meta, udp_profile_lidar=profile)
    assert other.packet_bytes == size
    valid = np.ones((32, 16), dtype=bool)
    valid[3, :5] = False
    valid[7, :] = False
    data = encode_ouster(other, real.measurement_id, real.timestamp_ns, real.frame_id, valid)
    assert data.shape == (32, size)
    cols = decode_ouster_columns(data, other)
    np.testing.assert_array_equal(cols.timestamp_ns, real.timestamp_ns)
    np.testing.assert_array_equal(cols.measurement_id, real.measurement_id)
    np.testing.assert_array_equal(cols.frame_id, real.frame_id)
    np.testing.assert_array_equal(cols.valid, valid)
    np.testing.assert_array_equal(np.isnan(cols.azimuth_deg), ~valid)
    np.testing.assert_allclose(cols.azimuth_deg[valid], real.azimuth_deg[valid])
    timing = decode_ouster(data, other)
    assert timing.sensor_time_ns[3] == real.timestamp_ns[3, 5]  # first valid column
    assert timing.sensor_time_ns[7] == real.timestamp_ns[7, 0]  # none valid: column 0
    assert bool(timing.dual_return[0]) == profile.endswith("DUAL")


def test_legacy_azimuth_comes_from_the_encoder(meta: OusterMetadata) -> None:
    legacy = dataclasses.replace(meta, udp_profile_lidar="LEGACY")
    mid = np.arange(16, dtype=np.int64)[np.newaxis, :] + 496
    data = encode_ouster(legacy, mid, 1000 + mid, np.array([5]))
    encoder_bytes = data[0, 12:16]  # column 0's u32 encoder count
    assert int.from_bytes(encoder_bytes.tobytes(), "little") == 496 * 176
    data[0, 12:16] = np.frombuffer((45056).to_bytes(4, "little"), np.uint8)  # half a turn
    cols = decode_ouster_columns(data, legacy)
    assert cols.azimuth_deg[0, 0] == 180.0
    assert cols.azimuth_deg[0, 1] == pytest.approx(360.0 * 497 / 512)
    data[0, 12:16] = np.frombuffer((90112).to_bytes(4, "little"), np.uint8)
    with pytest.raises(DecodeError, match="out of range"):
        decode_ouster_columns(data, legacy)


def test_message_framing_matches_rosbags(rec: Recording) -> None:
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg("uint8[] buf", "ouster_sensor_msgs/msg/PacketMsg"))
    msg_type = store.types["ouster_sensor_msgs/msg/PacketMsg"]
    buf = rec.packets[0]
    msg = msg_type(buf=buf)
    for encoding in ("ros1", "cdr"):
        built = build_ouster_packet_msg(buf, encoding)
        if encoding == "ros1":
            reference = store.serialize_ros1(msg, "ouster_sensor_msgs/msg/PacketMsg")
        else:
            reference = store.serialize_cdr(msg, "ouster_sensor_msgs/msg/PacketMsg")
        assert built == reference.tobytes()
        view = ouster_packet_bytes(built, encoding)
        np.testing.assert_array_equal(view, buf)
    raw = bytearray(build_ouster_packet_msg(buf, "cdr") + b"\x00\x00")  # CDR end padding
    view = ouster_packet_bytes(raw, "cdr")
    raw[8] ^= 0xFF
    assert view[0] == raw[8]  # zero-copy: the view sees the change
    big_endian = b"\x00\x00\x00\x00" + struct.pack(">I", 3) + b"abc"
    assert ouster_packet_bytes(big_endian, "cdr").tobytes() == b"abc"


@pytest.mark.parametrize(
    ("raw", "encoding"),
    [
        (b"\x05\x00\x00\x00abcd", "ros1"),
        (b"\x03\x00\x00\x00abcd", "ros1"),
        (b"\x00\x01", "cdr"),
        (b"\x00\x07\x00\x00\x04\x00\x00\x00abcd", "cdr"),
        (b"\x00\x01\x00\x00\x09\x00\x00\x00abcd", "cdr"),
    ],
)
def test_malformed_messages_raise(raw: bytes, encoding: Any) -> None:
    with pytest.raises(DecodeError):
        ouster_packet_bytes(raw, encoding)


def test_malformed_packets_raise(rec: Recording, meta: OusterMetadata) -> None:
    with pytest.raises(DecodeError, match="8448 bytes"):
        decode_ouster(rec.packets[:, :-1], meta)
    with pytest.raises(DecodeError, match="24896 bytes"):
        decode_ouster(rec.packets[:, :8000], dataclasses.replace(meta, udp_profile_lidar="LEGACY"))
    imu_like = rec.packets[:2].copy()
    imu_like[1, 0] = 2
    with pytest.raises(DecodeError, match="packet_type"):
        decode_ouster(imu_like, meta)
    wrong_mode = dataclasses.replace(meta, columns_per_frame=256)
    with pytest.raises(DecodeError, match="out of range"):
        decode_ouster(rec.packets, wrong_mode)


def test_declared_rate_from_lidar_mode(rec: Recording, meta: OusterMetadata) -> None:
    """The metadata's lidar_mode is the rate the sensor declares; a mismatch is warned."""
    scanner = LidarScanner.create("/os_node0/lidar_packets")
    timing = decode_ouster(rec.packets, meta)
    assert timing.motor_rpm is not None and (timing.motor_rpm == 600.0).all()
    scanner.feed(packet_samples(timing, rec.log_time_ns), messages=32)
    assert scanner.finish().warnings == []
    # The same packets under metadata claiming 512x20 (1200 RPM): they still turn at 600.
    wrong = dataclasses.replace(meta, rotation_rate_hz=20, lidar_mode="512x20")
    scanner = LidarScanner.create("/os_node0/lidar_packets")
    scanner.feed(packet_samples(decode_ouster(rec.packets, wrong), rec.log_time_ns), messages=32)
    scan = scanner.finish()
    assert scan.declared_rpm == 1200.0
    (warning,) = scan.warnings
    assert "1200 RPM of the metadata's lidar_mode" in warning


@pytest.mark.parametrize(
    ("head", "accepted"),
    [(b"\x00\x01", True), (b"\x00\x00", True), (b"\x00\x02", False), (b"\x00\x03", False)],
)
def test_packet_msg_takes_plain_cdr_only(head: bytes, accepted: bool) -> None:
    """CDR_LE/CDR_BE as every reader of logs.wire; a parameter list (PL_CDR) is refused."""
    from syncaudit.lidar.ouster import ouster_packet_bytes

    order = "<" if head[1] & 1 else ">"
    raw = head + b"\x00\x00" + struct.pack(order + "I", 4) + b"\x01\x02\x03\x04"
    if accepted:
        assert bytes(ouster_packet_bytes(raw, "cdr")) == b"\x01\x02\x03\x04"
    else:
        with pytest.raises(DecodeError, match="CDR encapsulation"):
            ouster_packet_bytes(raw, "cdr")
