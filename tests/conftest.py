"""Shared fixtures: the real recordings in ../shared/data, skipped only when absent."""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_LIDAR = REPO.parent / "shared" / "data" / "lidar"


@pytest.fixture(scope="session")
def lidar_data() -> Path:
    """Folder of real LiDAR recordings; skip the test when the shared data is absent."""
    if not SHARED_LIDAR.is_dir():
        pytest.skip(f"real recordings not found at {SHARED_LIDAR} (../shared/data is absent)")
    return SHARED_LIDAR


SHARED_PCAP = REPO.parent / "shared" / "data" / "pcap"


@pytest.fixture(scope="session")
def pcap_data() -> Path:
    """Folder of real LiDAR network captures; skip the test when the shared data is absent."""
    if not SHARED_PCAP.is_dir():
        pytest.skip(f"real captures not found at {SHARED_PCAP} (../shared/data is absent)")
    return SHARED_PCAP
