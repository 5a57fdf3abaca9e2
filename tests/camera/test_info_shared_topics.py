"""`info` shows a topic several cameras share as those cameras, as `audit` routes its messages.

A driver node serving several cameras publishes them all on one topic, told apart by
`header.frame_id` (or the `camera` field of the syncaudit types). `info` must list one
camera per frame id with the messages each gets, agree with `audit` and the rig guess on
it, and show a log of one topic per camera exactly as before.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from syncaudit.audit.inspect import InfoReport, inspect_log
from syncaudit.audit.rig_guess import guess_rig
from syncaudit.audit.run import audit_log
from syncaudit.cli import app
from syncaudit.logs import open_log
from syncaudit.simulate.rig_file import rig_from_truth
from syncaudit.simulate.sync_log import CameraSim, SyncSimConfig, simulate_sync_log

CAMERAS = [
    CameraSim(name="front", yaw_deg=0.0),
    CameraSim(name="left", yaw_deg=100.0),
    CameraSim(name="rear", yaw_deg=200.0),
]
runner = CliRunner()


def _log(tmp_path: Path, log_format: str, **config: Any) -> tuple[Path, dict[str, Any]]:
    out = tmp_path / f"log.{log_format}"
    cfg = SyncSimConfig(cameras=CAMERAS, duration_s=2.0, seed=11, log_format=log_format, **config)
    return out, simulate_sync_log(out, cfg)


def _frames(truth: dict[str, Any]) -> dict[str, int]:
    return {name: len(cam["frames"]) for name, cam in truth["cameras"].items()}


@pytest.mark.parametrize("log_format", ["mcap", "bag"])
def test_info_splits_a_shared_topic_by_frame_id_as_the_audit_does(
    tmp_path: Path, log_format: str
) -> None:
    out, truth = _log(
        tmp_path,
        log_format,
        exposure_messages=("flir_meta",),
        shared_topics=("image", "meta", "trigger"),
        camera_field=False,
    )
    frames = _frames(truth)
    report = inspect_log(out)
    assert {c.name: c.frames for c in report.cameras} == frames
    for cam in report.cameras:
        assert cam.frame_id == f"{cam.name}_optical_frame"
        assert cam.image_topic == "/cameras/image_raw"
        assert cam.shared_topics == ("/cameras/image_raw", "/cameras/meta", "/cameras/trigger")
        assert cam.rate_hz == pytest.approx(frames[cam.name] / report.duration_s)
    assert [(s.topic, s.kind) for s in report.shared_topics] == [
        ("/cameras/image_raw", "image"),
        ("/cameras/meta", "exposure"),
        ("/cameras/trigger", "trigger"),
    ]
    for row in report.shared_topics:
        assert row.messages == sum(frames.values())
        assert row.cameras == {c.name: frames[c.name] for c in report.cameras}
        assert row.frame_ids == {f"{n}_optical_frame": k for n, k in sorted(frames.items())}
        assert row.unnamed == row.damaged == 0 and row.unknown == {}
    assert not [w for w in report.warnings if "shared by cameras" in w]
    # The same cameras the rig guess and the audit find, with the audit's frame counts.
    with open_log(out) as log:
        rig, _ = guess_rig(log)
    assert [c.name for c in report.cameras] == [c.name for c in rig.cameras]
    audited = audit_log(out, jobs=1)
    assert {c.sync.camera: c.sync.frames_total for c in audited.cameras} == frames
    # With the simulator's rig: the same counts.
    with_rig = inspect_log(out, rig_from_truth(truth))
    assert {c.name: c.frames for c in with_rig.cameras} == frames
    assert [s.cameras for s in with_rig.shared_topics] == [s.cameras for s in report.shared_topics]


@pytest.mark.parametrize("log_format", ["mcap", "bag"])
def test_info_of_a_log_with_one_topic_per_camera_is_unchanged(
    tmp_path: Path, log_format: str
) -> None:
    out, truth = _log(tmp_path, log_format)
    frames = _frames(truth)
    report = inspect_log(out)
    assert {c.name: c.frames for c in report.cameras} == frames
    assert report.shared_topics == []
    for cam in report.cameras:
        assert cam.shared_topics == ()
        assert cam.image_topic == f"/cameras/{cam.name}/image_raw"
    table = runner.invoke(app, ["info", str(out)])
    assert table.exit_code == 0, table.output
    assert "frame id" not in table.stdout and "shared by several" not in table.stdout


def test_info_counts_what_the_audit_cannot_route(tmp_path: Path) -> None:
    """No frame id and no camera field: the shared topic's messages go to no camera, and
    `info` says so with the audit's own warning."""
    out, truth = _log(
        tmp_path,
        "bag",
        exposure_messages=("flir_meta",),
        shared_topics=("image", "meta"),
        camera_field=False,
        header_frame_ids=False,
    )
    total = sum(_frames(truth).values())
    report: InfoReport = inspect_log(out, rig_from_truth(truth))
    assert [c.frames for c in report.cameras] == [0, 0, 0]
    image = report.shared_topics[0]
    assert (image.topic, image.messages, image.unnamed) == ("/cameras/image_raw", total, total)
    assert image.frame_ids == {"": total}
    assert set(image.cameras.values()) == {0}
    assert any("/cameras/image_raw" in w and "no header.frame_id" in w for w in report.warnings)


def test_info_json_and_table_name_the_cameras_of_a_shared_topic(tmp_path: Path) -> None:
    out, truth = _log(tmp_path, "mcap", shared_topics=("image", "exposure", "trigger"))
    frames = _frames(truth)
    result = runner.invoke(app, ["info", str(out), "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert {c["name"]: c["frames"] for c in data["cameras"]} == frames
    assert data["shared_topics"][0]["cameras"] == {n: frames[n] for n in ("front", "left", "rear")}
    table = runner.invoke(app, ["info", str(out)])
    assert table.exit_code == 0, table.output
    assert "Topics shared by several cameras" in table.stdout
    for name, count in frames.items():
        assert f"{name}_optical_frame {count}" in table.stdout
