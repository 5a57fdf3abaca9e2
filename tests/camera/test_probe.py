"""The camera probe of the rig guess reads the syncaudit camera messages' `camera` field by
struct (no type registry built from the log's schemas), with rosbags' result, and still
fails on a damaged one as it always has (through rosbags)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from mcap.records import Channel, Message, Schema

from mcap_copy import copy_mcap
from syncaudit.camera import camera_topics as topics
from syncaudit.camera.extract import CAMERA_FIELD_TYPES
from syncaudit.errors import LogReadError
from syncaudit.logs import open_log
from syncaudit.simulate.sync_log import CameraSim, SyncSimConfig, simulate_sync_log

CAMERAS = [CameraSim(name="front", yaw_deg=0.0), CameraSim(name="left", yaw_deg=100.0)]


@pytest.fixture(scope="module")
def shared_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("probe") / "log.mcap"
    simulate_sync_log(
        out,
        SyncSimConfig(
            cameras=CAMERAS, duration_s=1.5, seed=3, shared_topics=("image", "exposure", "trigger")
        ),
    )
    return out


def _probe(path: Path) -> topics.CameraProbe:
    with open_log(path) as log:
        return topics.probe_camera_topics(log, list(log.topics))


def test_probe_reads_camera_fields_without_the_type_registry(
    shared_log: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    by_rosbags = None
    with monkeypatch.context() as patch:
        patch.setattr(topics, "read_fast", lambda *args: None)  # every message via rosbags
        by_rosbags = _probe(shared_log)
    # image (by frame id), exposure and trigger (by their `camera` field)
    assert sorted(by_rosbags.shared.values()) == [
        ["front", "left"],
        ["front", "left"],
        ["front_optical_frame", "left_optical_frame"],
    ]

    def no_registry(self: Any, encoding: str) -> None:
        raise AssertionError("the probe built a type registry")

    with open_log(shared_log) as log:
        monkeypatch.setattr(type(log), "type_registry", no_registry)
        assert topics.probe_camera_topics(log, list(log.topics)) == by_rosbags


def test_a_damaged_camera_message_still_fails_the_probe(shared_log: Path, tmp_path: Path) -> None:
    """The first TriggerEvent cut short: rosbags' error, as before the struct path."""
    cut: list[int] = []

    def first_cut(schema: Schema, _channel: Channel, message: Message) -> bytes:
        if not cut and schema.name in CAMERA_FIELD_TYPES:
            cut.append(message.log_time)
            return message.data[:30]
        return message.data

    damaged = copy_mcap(shared_log, tmp_path / "damaged.mcap", change=first_cut)
    assert cut
    with pytest.raises(LogReadError, match="does not match its definition"):
        _probe(damaged)
