"""Fixtures of the report tests: a real audit of a sample log, calibration results."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from pathlib import Path

import pytest

from syncaudit.audit import AuditResult, audit_log
from syncaudit.calib.result import CalibrationResult
from syncaudit.rig import load_rig

REPO = Path(__file__).resolve().parents[2]
THREE_CAMERAS = REPO / "sample_logs" / "vlp16_three_cameras.mcap"
DATA = Path(__file__).resolve().parent / "data"
HOSTILE = '<script>alert("x")</script>&amp;'
"""Text a log could carry (a camera name, a topic, a frame id) that must show as text."""


@functools.cache
def _audit() -> AuditResult:
    return audit_log(THREE_CAMERAS, load_rig(Path(f"{THREE_CAMERAS}.rig.yaml")), jobs=1)


@pytest.fixture()
def audit() -> AuditResult:
    """The audit of the three-camera sample (real decoding; computed once per session)."""
    return _audit()


@pytest.fixture()
def hostile_audit() -> AuditResult:
    """The same audit with a camera name, the LiDAR topic and a warning holding markup."""
    base = _audit()
    first = dataclasses.replace(base.cameras[0])
    first.sync = dataclasses.replace(first.sync, camera=f"cam{HOSTILE}")
    return dataclasses.replace(
        base,
        path=f"/logs/{HOSTILE}.mcap",
        lidar=dataclasses.replace(base.lidar, topic=f"/lidar{HOSTILE}"),
        cameras=[first, *base.cameras[1:]],
        warnings=[*base.warnings, f"frame id {HOSTILE} unknown"],
    )


def _calibration(name: str) -> CalibrationResult:
    return CalibrationResult.model_validate_json((DATA / f"{name}.json").read_bytes())


@pytest.fixture()
def calibration() -> Callable[[str], CalibrationResult]:
    """Load a saved calibration result by name (tests/report/data, see its README)."""
    return _calibration


@pytest.fixture()
def hostile() -> str:
    """Markup that a log's text could carry."""
    return HOSTILE
