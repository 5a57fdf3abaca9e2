"""`info` reports a log's health (truncation, damaged records, bad chunk CRCs), `--check-crc`.

The damaged logs are the sample MCAP with one chunk's CRC field changed (it decompresses;
only the CRC tells), with a chunk's compressed bytes flipped, and cut at two thirds.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader

SAMPLE = Path(__file__).resolve().parents[2] / "sample_logs" / "vlp16_three_cameras.mcap"
CHUNK_CRC_AT = 1 + 8 + 24
"""Offset of a chunk record's uncompressed CRC: opcode, length, start, end, size."""


def _chunks() -> list[tuple[int, int]]:
    """(offset, length) of the sample's chunk records, in file order."""
    with SAMPLE.open("rb") as handle:
        summary = make_reader(handle).get_summary()
    assert summary is not None
    return sorted((c.chunk_start_offset, c.chunk_length) for c in summary.chunk_indexes)


def _chunk_offsets() -> list[int]:
    return [offset for offset, _ in _chunks()]


def _info(*args: str | Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "syncaudit", "info", *(str(a) for a in args)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )


@pytest.fixture
def bad_crc(tmp_path: Path) -> tuple[Path, int]:
    """The sample with chunk 1's CRC field changed: every byte else intact."""
    data = bytearray(SAMPLE.read_bytes())
    offset = _chunk_offsets()[1]
    data[offset + CHUNK_CRC_AT] ^= 0xFF
    path = tmp_path / "crc.mcap"
    path.write_bytes(bytes(data))
    return path, offset


def test_check_crc_lists_the_bad_chunk_and_exits_3(bad_crc: tuple[Path, int]) -> None:
    path, offset = bad_crc
    done = _info(path, "--check-crc", "--json")
    assert done.returncode == 3, done.stderr
    health = json.loads(done.stdout)["health"]
    assert health["status"] == "bad-crc"
    assert health["bad_crc_chunks"] == [offset]
    assert health["crc_checked_chunks"] == len(_chunk_offsets())
    assert done.stderr.strip() == f"error: {path}: 1 MCAP chunk(s) fail their CRC, at byte {offset}"


def test_without_check_crc_info_says_crcs_were_not_checked(bad_crc: tuple[Path, int]) -> None:
    path, _ = bad_crc
    done = _info(path)
    assert done.returncode == 0, done.stderr
    assert "health ok; chunk CRCs not checked (--check-crc)" in done.stdout


def test_healthy_log_checks_every_chunk() -> None:
    done = _info(SAMPLE, "--check-crc")
    assert done.returncode == 0, done.stderr
    assert f"health ok; {len(_chunk_offsets())} chunk CRCs checked, 0 bad" in done.stdout


def test_undecompressable_chunk_is_damage(tmp_path: Path) -> None:
    data = bytearray(SAMPLE.read_bytes())
    offset, length = _chunks()[0]
    data[offset + length // 2] ^= 0xFF  # inside the zstd frame
    path = tmp_path / "zstd.mcap"
    path.write_bytes(bytes(data))
    done = _info(path, "--json")
    assert done.returncode == 3
    health = json.loads(done.stdout)["health"]
    assert health["status"] == "damaged" and "corrupt" in health["damaged"][0]


def test_cut_log_is_truncated(tmp_path: Path) -> None:
    data = SAMPLE.read_bytes()
    path = tmp_path / "cut.mcap"
    path.write_bytes(data[: len(data) * 2 // 3])
    done = _info(path, "--json", "--check-crc")
    assert done.returncode == 0, done.stderr
    health = json.loads(done.stdout)["health"]
    assert health["status"] == "truncated" and health["truncated"] is True
    assert any("cut off" in note for note in health["notes"])
    assert health["crc_note"] == "no chunk CRCs checked: the MCAP has no chunk index"


def test_formats_without_crcs_say_so() -> None:
    done = _info(SAMPLE.with_name("vlp16_short.bag"), "--check-crc", "--json")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["health"]["crc_note"].endswith("a rosbag1 log holds none")
