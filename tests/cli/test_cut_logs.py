"""A log cut off before its LiDAR's first packet: `audit` names the file and the cut, exit 3."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"
BAG = SAMPLES / "vlp16_short.bag"


@pytest.mark.parametrize("command", ["audit", "info"])
def test_bag_cut_before_lidar_packets_names_file_and_cut(tmp_path: Path, command: str) -> None:
    cut = tmp_path / "cut.bag"
    cut.write_bytes(BAG.read_bytes()[:50_000])
    done = subprocess.run(
        [sys.executable, "-m", "syncaudit", command, str(cut), "--rig", f"{BAG}.rig.yaml"],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 3, done.stderr  # damaged beyond reading, not "no data" (7)
    assert done.stderr.strip().splitlines() == [
        f"error: {cut}: ROS 1 bag cut off at byte 50000 (recording interrupted?): "
        "LiDAR topic /velodyne_packets holds no packets before it"
    ]
