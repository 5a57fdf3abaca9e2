"""Cameras that share one topic get their own frames, told apart by header.frame_id.

Real rigs publish per-frame camera messages both ways: one topic per camera (the ROS 2
spinnaker_camera_driver, one node per camera with its own `frame_id` parameter; Autoware's
`/sensing/camera/cameraN/...`), or one topic for several cameras told apart only by
`header.frame_id` (one driver node for a multi-camera board; ximea_ros_cam issue 38 asks for
four cameras on `ximea_cam/image_raw`). Drivers also leave frame_id empty
(avt_vimba_camera PR 11) or give every camera the same one (Autoware PR 1296, "camera";
grand_tour_box issue 465): then nothing in the messages tells the cameras apart.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from syncaudit.audit.rig_guess import guess_rig
from syncaudit.audit.run import AuditResult, audit_log
from syncaudit.camera.camera_topics import frame_camera_name
from syncaudit.errors import ConfigError
from syncaudit.logs import open_log
from syncaudit.rig import Rig
from syncaudit.simulate.rig_file import rig_from_truth
from syncaudit.simulate.sync_log import CameraSim, SyncSimConfig, simulate_sync_log

CAMERAS = [
    CameraSim(name="front", yaw_deg=0.0, delay_error_us=300.0),
    CameraSim(name="left", yaw_deg=100.0, delay_error_us=-500.0),
    CameraSim(name="rear", yaw_deg=200.0, stamp_semantics="exposure_end"),
]
ERROR_NS = 5_000
"""Per-camera Eq. 5 against the truth: the packets' 0.01 deg azimuths give ~2.5 us."""


def _run(tmp_path: Path, **config: Any) -> tuple[AuditResult, dict[str, Any]]:
    out = tmp_path / f"log.{config.get('log_format', 'mcap')}"
    config = {"cameras": CAMERAS, "duration_s": 3.0, "seed": 5, **config}
    truth = simulate_sync_log(out, SyncSimConfig(**config))
    return audit_log(out, rig_from_truth(truth), jobs=1), truth


def _assert_each_camera_has_its_own_frames(result: AuditResult, truth: dict[str, Any]) -> None:
    assert [c.sync.camera for c in result.cameras] == [c.name for c in CAMERAS]
    for cam in result.cameras:
        sync, t = cam.sync, truth["cameras"][cam.sync.camera]
        assert sync.frames_total == sync.frames_paired == len(t["frames"]), sync.camera
        # Its own exposures (to the microsecond ImageMetaData holds), none of the others'.
        starts = np.sort(sync.frames["exposure_start_ns"].to_numpy(np.int64))
        truth_starts = np.sort([f["exposure_start_ns"] for f in t["frames"]])
        assert np.max(np.abs(starts - truth_starts)) <= 1_000, sync.camera
        assert sync.error_mean_ns == pytest.approx(t["error_mean_ns"], abs=ERROR_NS)
        assert sync.judged, sync.not_judged_reason


@pytest.mark.parametrize("log_format", ["mcap", "bag"])
def test_shared_image_meta_and_trigger_topics_told_apart_by_frame_id(
    tmp_path: Path, log_format: str
) -> None:
    """frame_id is the only field telling the cameras apart (no `camera` field)."""
    result, truth = _run(
        tmp_path,
        log_format=log_format,
        exposure_messages=("flir_meta",),
        shared_topics=("image", "meta", "trigger"),
        camera_field=False,
    )
    topics = {t["topics"]["image"] for t in truth["cameras"].values()}
    assert topics == {"/cameras/image_raw"}
    _assert_each_camera_has_its_own_frames(result, truth)
    for cam in result.cameras:  # triggers routed too: t2..t4 observed, not assumed
        assert cam.sync.latencies["t3"].status == "observed"
        assert cam.sync.packet_phase_source == "trigger packet"


def test_shared_image_topic_without_exposure_metadata(tmp_path: Path) -> None:
    """Frames from the shared image topic itself (the exposure assumed by the rig)."""
    out = tmp_path / "log.mcap"
    truth = simulate_sync_log(
        out,
        SyncSimConfig(
            cameras=CAMERAS, duration_s=3.0, seed=6, exposure_messages=(), shared_topics=("image",)
        ),
    )
    rig = rig_from_truth(truth)
    rig = rig.model_copy(
        update={
            "cameras": [c.model_copy(update={"assumed_exposure_us": 2000.0}) for c in rig.cameras]
        }
    )
    result = audit_log(out, rig, jobs=1)
    for cam in result.cameras:
        t = truth["cameras"][cam.sync.camera]
        assert cam.sync.frames_total == len(t["frames"])
        stamps = cam.sync.frames["header_stamp_ns"].to_numpy(np.int64).tolist()
        assert stamps == [f["image_stamp_ns"] for f in t["frames"]]


def test_shared_syncaudit_topics_told_apart_by_camera_field(tmp_path: Path) -> None:
    """CameraExposure and TriggerEvent name their camera: enough without any frame_id."""
    result, truth = _run(
        tmp_path,
        exposure_messages=("camera_exposure",),
        shared_topics=("image", "exposure", "trigger"),
        header_frame_ids=False,
    )
    _assert_each_camera_has_its_own_frames(result, truth)


def test_shared_topic_without_frame_ids_is_not_judged_with_the_reason(tmp_path: Path) -> None:
    result, truth = _run(
        tmp_path,
        exposure_messages=("flir_meta",),
        shared_topics=("image", "meta", "trigger"),
        camera_field=False,
        header_frame_ids=False,
    )
    assert result.verdict == "not judged"
    assert len(result.cameras) == len(CAMERAS)
    for cam in result.cameras:
        assert not cam.sync.judged
        assert cam.sync.frames_total == 0
        reason = cam.sync.not_judged_reason or ""
        assert "/cameras/meta" in reason and "frame_id" in reason, reason
    shared = [w for w in result.warnings if "/cameras/meta" in w and "no header.frame_id" in w]
    assert len(shared) == 1, result.warnings
    assert f"{len(CAMERAS) * len(truth['cameras']['front']['frames'])} messages" in shared[0]


def test_frame_id_naming_no_camera_of_the_rig_is_warned(tmp_path: Path) -> None:
    """A rig whose frame_id does not match the messages: that camera gets nothing."""
    out = tmp_path / "log.mcap"
    truth = simulate_sync_log(
        out,
        SyncSimConfig(
            cameras=CAMERAS,
            duration_s=3.0,
            seed=7,
            exposure_messages=("flir_meta",),
            shared_topics=("image", "meta"),
        ),
    )
    data = rig_from_truth(truth).model_dump()
    data["cameras"][1]["frame_id"] = "left_camera_link"  # the messages say left_optical_frame
    result = audit_log(out, Rig.model_validate(data), jobs=1)
    by_name = {c.sync.camera: c.sync for c in result.cameras}
    assert by_name["front"].judged and by_name["rear"].judged
    assert by_name["left"].frames_total == 0 and not by_name["left"].judged
    assert any("'left_optical_frame'" in w and "no camera" in w for w in result.warnings)


def test_rig_with_two_cameras_of_one_frame_id_on_a_shared_topic_is_refused() -> None:
    cams = [
        {"name": "a", "image_topic": "/cams/image", "frame_id": "camera", "azimuth_deg": 10.0},
        {"name": "b", "image_topic": "/cams/image", "frame_id": "camera", "azimuth_deg": 90.0},
    ]
    with pytest.raises(ConfigError, match="frame_id 'camera'"):
        Rig.model_validate({"lidar": {"topic": "/p"}, "cameras": cams})
    cams[1]["image_topic"] = "/cams/b/image"  # own topics: the same frame_id is harmless
    Rig.model_validate({"lidar": {"topic": "/p"}, "cameras": cams})


def test_without_a_rig_a_shared_topic_is_one_camera_per_frame_id(tmp_path: Path) -> None:
    """The guess reads the topics' first second: three frame ids on one image topic are
    three cameras, placed by /tf_static and each given its own frames."""
    out = tmp_path / "log.mcap"
    truth = simulate_sync_log(
        out,
        SyncSimConfig(
            cameras=CAMERAS,
            duration_s=3.0,
            seed=8,
            exposure_messages=("flir_meta",),
            shared_topics=("image", "meta", "trigger"),
            camera_field=False,
        ),
    )
    with open_log(out) as log:
        rig, guessed = guess_rig(log)
    assert sorted(c.name for c in rig.cameras) == sorted(c.name for c in CAMERAS)
    for cam in rig.cameras:
        assert cam.frame_id == truth["cameras"][cam.name]["frame_id"]
        assert (cam.image_topic, cam.exposure_topic, cam.trigger_topic) == (
            "/cameras/image_raw",
            "/cameras/meta",
            "/cameras/trigger",
        )
    assert any("/cameras/image_raw shared by 3 cameras" in g for g in guessed)
    result = audit_log(out, jobs=1)
    for cam in result.cameras:
        t = truth["cameras"][cam.sync.camera]
        assert "/tf_static" in cam.azimuth_source
        assert cam.sync.frames_total == len(t["frames"])
        assert cam.sync.frames_paired >= len(t["frames"]) - 1  # no zero azimuth: see rig_guess


def test_frame_camera_names() -> None:
    assert frame_camera_name("cam_front_optical_frame") == "cam_front"
    assert frame_camera_name("/vehicle/camera3_link") == "camera3"
    assert frame_camera_name("camera") == "camera"
