"""Fixtures of the fleet tests: the bundled sample logs and their audits, computed once."""

from __future__ import annotations

from pathlib import Path

import pytest

from syncaudit.fleet.inputs import LogJob
from syncaudit.fleet.job import JobOptions, LogOutcome, run_log_job

REPO = Path(__file__).resolve().parents[2]
SAMPLES = REPO / "sample_logs"
THREE_CAMERAS = SAMPLES / "vlp16_three_cameras.mcap"


@pytest.fixture(scope="session")
def three_cameras_outcome() -> LogOutcome:
    """The audit of the three-camera sample log (real decoding, its own rig)."""
    job = LogJob(path=str(THREE_CAMERAS), rig_path=str(THREE_CAMERAS) + ".rig.yaml")
    outcome = run_log_job(job, JobOptions())
    assert outcome.ok, outcome.error
    return outcome


@pytest.fixture()
def small_fleet(tmp_path: Path) -> Path:
    """A fleet folder of two vehicles: symlinks to sample logs and their rigs."""
    root = tmp_path / "uploads"
    for vehicle, names in (
        ("car1", ["vlp16_three_cameras.mcap"]),
        ("car2", ["pandar40p_adaptive.mcap"]),
    ):
        folder = root / vehicle
        folder.mkdir(parents=True)
        for name in names:
            (folder / name).symlink_to(SAMPLES / name)
            (folder / f"{name}.rig.yaml").symlink_to(SAMPLES / f"{name}.rig.yaml")
    return root
