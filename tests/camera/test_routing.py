"""CameraRouter on hand-made rows: who gets what from a topic cameras share."""

from __future__ import annotations

from typing import Any

import pytest

from syncaudit.camera.extract import CameraTableBuilder
from syncaudit.camera.routing import CameraRouter
from syncaudit.camera.rowstore import DamagedRow
from syncaudit.errors import LogReadError
from syncaudit.rig import CameraConfig

T0 = 1_700_000_000_000_000_000


def _router(*frames: str | None) -> tuple[CameraRouter, list[CameraTableBuilder]]:
    router = CameraRouter()
    builders = []
    for i, frame in enumerate(frames):
        builder = CameraTableBuilder(CameraConfig(name=f"cam{i}", frame_id=frame))
        for kind in ("image", "exposure", "trigger"):
            router.add(kind, f"/shared/{kind}", builder)
        builders.append(builder)
    return router, builders


def _image(frame_id: str, i: int = 0) -> tuple[int, int, int | None, str]:
    return (T0 + i, T0 + i + 5, None, frame_id)


def _trigger(camera: str, frame_id: str) -> tuple[Any, ...]:
    return (
        camera,
        0,
        T0,
        None,
        None,
        None,
        T0,
        None,
        None,
        "sensor_msgs/msg/TimeReference",
        frame_id,
    )


def test_rows_go_to_the_camera_of_their_frame_id() -> None:
    router, (a, b) = _router("a_optical", "b_optical")
    for i in range(3):
        router.feed("image", "/shared/image", _image("a_optical", i))
    router.feed("image", "/shared/image", _image("b_optical"))
    assert router.finish() == []
    assert len(a.images) == 3 and len(b.images) == 1
    assert not a.shared_topic_notes and not b.shared_topic_notes


def test_camera_field_comes_before_frame_id() -> None:
    router, (a, b) = _router("a_optical", "b_optical")
    router.feed("trigger", "/shared/trigger", _trigger("cam1", "a_optical"))
    router.finish()
    assert (len(a.triggers), len(b.triggers)) == (0, 1)


def test_unnamed_images_are_left_out_and_the_cameras_told_why() -> None:
    router, builders = _router("a_optical", "b_optical")
    router.feed("image", "/shared/image", _image(""))
    router.feed("image", "/shared/image", _image("", 1))
    (warning,) = router.finish()
    assert "/shared/image" in warning and "2 messages carry no header.frame_id" in warning
    for builder in builders:
        assert len(builder.images) == 0
        assert "carry no header.frame_id" in builder.shared_topic_notes[0]


def test_unnamed_triggers_are_offered_to_every_camera() -> None:
    router, builders = _router("a_optical", "b_optical")
    router.feed("trigger", "/shared/trigger", _trigger("", ""))
    (warning,) = router.finish()
    assert "offered to every camera" in warning
    assert [len(b.triggers) for b in builders] == [1, 1]


def test_a_camera_without_frame_id_on_a_shared_topic_is_told() -> None:
    router, (a, b) = _router("a_optical", None)
    router.feed("image", "/shared/image", _image("a_optical"))
    router.finish()
    assert len(a.images) == 1 and len(b.images) == 0
    assert "gives the camera no frame_id" in b.shared_topic_notes[0]


def test_damaged_rows_of_a_shared_topic() -> None:
    router, (a, _) = _router("a_optical", "b_optical")
    damaged = DamagedRow("/shared/image", T0, "8 bytes cannot hold a header stamp")
    router.feed("image", "/shared/image", damaged)
    router.feed("image", "/shared/image", _image("a_optical"))
    (warning,) = router.finish()
    assert "1 damaged messages skipped" in warning and len(a.images) == 1
    router, _ = _router("a_optical", "b_optical")
    router.feed("image", "/shared/image", damaged)
    with pytest.raises(LogReadError, match="all 1 messages on image topic /shared/image"):
        router.finish()


def test_a_topic_of_one_camera_takes_every_row_as_it_is() -> None:
    router = CameraRouter()
    builder = CameraTableBuilder(CameraConfig(name="solo", frame_id="solo_optical"))
    router.add("image", "/solo/image", builder)
    router.feed("image", "/solo/image", _image("something_else"))
    router.feed("image", "/solo/image", _image(""))
    assert router.finish() == [] and len(builder.images) == 2


def test_a_leading_slash_of_ros1_frame_ids_is_ignored() -> None:
    router, (a, b) = _router("a_optical", "/b_optical")
    router.feed("image", "/shared/image", _image("/a_optical"))
    router.feed("image", "/shared/image", _image("b_optical"))
    assert router.finish() == []
    assert (len(a.images), len(b.images)) == (1, 1)
