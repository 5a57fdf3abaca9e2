"""Other camera inputs of the same simulated drive: flir metadata, /tf_static, CameraInfo."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from syncaudit.audit.run import audit_log
from syncaudit.rig import Rig
from syncaudit.simulate.rig_file import rig_from_truth
from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    out = tmp_path_factory.mktemp("cams") / "log.mcap"
    return out, simulate_sync_log(out, SyncSimConfig(seed=71, duration_s=3.0))


def _rig(truth: dict[str, Any], **camera_changes: Any) -> Rig:
    data = rig_from_truth(truth).model_dump()
    for cam in data["cameras"]:
        name = cam["name"]
        for key, value in camera_changes.items():
            cam[key] = value(name, truth["cameras"][name]) if callable(value) else value
    return Rig.model_validate(data)


def test_flir_image_metadata_gives_the_same_errors(drive: tuple[Path, dict[str, Any]]) -> None:
    out, truth = drive
    rig = _rig(truth, exposure_topic=lambda _n, cam: cam["topics"]["meta"])
    reference = audit_log(out, rig_from_truth(truth), jobs=1)
    flir = audit_log(out, rig, jobs=1)
    for a, b in zip(reference.cameras, flir.cameras, strict=True):
        assert b.sync.frames_paired == a.sync.frames_paired > 0
        # ImageMetaData carries exposure in whole microseconds: t_l moves by < 0.5 us.
        diff = b.sync.frames["t_l_ns"].to_numpy() - a.sync.frames["t_l_ns"].to_numpy()
        assert np.max(np.abs(diff)) <= 500


def test_camera_azimuth_from_tf_static(drive: tuple[Path, dict[str, Any]]) -> None:
    out, truth = drive
    rig = _rig(truth, azimuth_deg=None)
    assert rig.lidar.azimuth_of_x_axis_deg is not None
    result = audit_log(out, rig, jobs=1)
    for cam in result.cameras:
        assert cam.azimuth_source.startswith("/tf_static")
        expected = truth["cameras"][cam.sync.camera]["azimuth_deg"] % 360.0
        assert abs((cam.azimuth_deg - expected + 180.0) % 360.0 - 180.0) < 1e-6


def test_camera_without_azimuth_is_skipped_with_a_reason(
    drive: tuple[Path, dict[str, Any]],
) -> None:
    out, truth = drive
    rig = _rig(truth, azimuth_deg=None, frame_id=None)
    result = audit_log(out, rig, jobs=1)
    assert result.cameras == []
    assert sum("skipped" in w for w in result.warnings) == len(truth["cameras"])
