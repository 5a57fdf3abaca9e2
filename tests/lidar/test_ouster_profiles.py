"""Ouster profiles of firmware 2.x-3.x and older metadata: what the real captures' JSON says,
and what is derived (with a note) where older metadata omits it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from syncaudit.lidar import ouster

OS1_128_FUSA = "OS-1-128_767798045_1024x10_20230712_120049.json"
OS0_128 = "OS-0-128-U1_v2.3.0_1024x10.json"
OS1_32 = "OS-1-32-G_v2.1.1_1024x10.json"

# (profile, pixel bytes as in ouster-sdk's profile table), 128 pixels, 16 columns.
PROFILES = [
    ("LEGACY", 12),
    ("RNG19_RFL8_SIG16_NIR16", 12),
    ("RNG19_RFL8_SIG16_NIR16_DUAL", 16),
    ("RNG15_RFL8_NIR8", 4),
    ("FIVE_WORD_PIXEL", 20),
    ("FUSA_RNG15_RFL8_NIR8_DUAL", 8),
]


def _json(pcap_data: Path, name: str) -> dict[str, Any]:
    loaded: dict[str, Any] = json.loads((pcap_data / name).read_text())
    return loaded


def test_fusa_dual_metadata_is_read(pcap_data: Path) -> None:
    meta = ouster.parse_ouster_metadata((pcap_data / OS1_128_FUSA).read_text())
    assert meta.udp_profile_lidar == "FUSA_RNG15_RFL8_NIR8_DUAL"
    assert meta.prod_line == "OS-1-128"
    assert meta.packet_bytes == 16640  # the capture's packets (README)
    assert meta.notes == ()


@pytest.mark.parametrize(("profile", "pixel_bytes"), PROFILES)
def test_every_profile_round_trips(pcap_data: Path, profile: str, pixel_bytes: int) -> None:
    root = _json(pcap_data, OS1_128_FUSA)
    root["lidar_data_format"]["udp_profile_lidar"] = profile
    meta = ouster.parse_ouster_metadata(json.dumps(root))
    header = 16 + 4 if profile == "LEGACY" else 12
    extra = 0 if profile == "LEGACY" else 64
    assert meta.packet_bytes == extra + 16 * (header + 128 * pixel_bytes)
    mid = np.arange(32).reshape(2, 16)
    ts = 1_000_000 + mid * 97_656
    packets = ouster.encode_ouster(meta, mid, ts, np.array([7, 7]))
    timing = ouster.decode_ouster(packets, meta)
    np.testing.assert_array_equal(timing.block_time_ns, ts)
    np.testing.assert_allclose(timing.block_azimuth_deg, 360.0 * mid / 1024)
    assert bool(timing.dual_return[0]) == profile.endswith("_DUAL")
    assert int(timing.return_mode[0]) == ouster.UDP_PROFILE_CODES[profile]


def test_missing_prod_line_is_derived_from_the_beams(pcap_data: Path) -> None:
    for name, line in ((OS0_128, "OS-0-128"), (OS1_32, "OS-1-32")):
        root = _json(pcap_data, name)
        del root["prod_line"]
        meta = ouster.parse_ouster_metadata(json.dumps(root))
        assert meta.prod_line == line
        assert any("no prod_line" in note for note in meta.notes)


def test_missing_format_fields_are_derived_and_fitted_to_the_packet_size(
    pcap_data: Path,
) -> None:
    root = _json(pcap_data, OS0_128)
    for key in ("columns_per_packet", "pixels_per_column", "udp_profile_lidar"):
        del root["data_format"][key]
    meta = ouster.parse_ouster_metadata(json.dumps(root))
    assert meta.pixels_per_column == 128
    assert meta.udp_profile_lidar == "LEGACY"
    assert not meta.stated_shape
    fitted = ouster.fit_packet_size(meta, 8448)  # the capture's RNG15_RFL8_NIR8 packets
    assert fitted is not None
    assert (fitted.udp_profile_lidar, fitted.columns_per_packet) == ("RNG15_RFL8_NIR8", 16)
    assert "8448-byte packets" in fitted.notes[-1]
    assert ouster.fit_packet_size(meta, 48) is None  # an IMU packet fits no lidar profile


def test_stated_shape_is_never_refitted(pcap_data: Path) -> None:
    meta = ouster.parse_ouster_metadata((pcap_data / OS0_128).read_text())
    assert ouster.fit_packet_size(meta, meta.packet_bytes) is meta
    assert ouster.fit_packet_size(meta, 6464) is None


def test_no_data_format_at_all_is_legacy_with_a_note(pcap_data: Path) -> None:
    root = _json(pcap_data, OS1_32)
    del root["data_format"]
    meta = ouster.parse_ouster_metadata(json.dumps(root))
    assert meta.packet_bytes == 6464
    assert meta.notes and "no data_format" in meta.notes[0]
