"""Works without a rig where the log says enough (issue 9, item 7)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from syncaudit.audit.rig_guess import starter_rig_yaml
from syncaudit.audit.run import audit_log
from syncaudit.camera.azimuth import X_AXIS_AZIMUTH_DEG, x_axis_azimuth_deg
from syncaudit.camera.camera_topics import detect_cameras, header_frame_id
from syncaudit.cli import app
from syncaudit.logs import RawMessage, TopicInfo, open_log
from syncaudit.rig import LidarConfig, load_rig
from syncaudit.simulate import LidarModel
from syncaudit.simulate.rig_file import rig_from_truth
from syncaudit.simulate.sync_log import _X_AXIS_AZIMUTH_DEG as SIMULATED_X_AXIS
from syncaudit.simulate.sync_log import CameraSim, SyncSimConfig, simulate_sync_log
from syncaudit.writers.provenance import COMMENT_MARK

SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"
THREE = SAMPLES / "vlp16_three_cameras.mcap"


def _truth(log: Path) -> dict[str, dict[str, float]]:
    cameras: dict[str, dict[str, float]] = json.loads(Path(f"{log}.truth.json").read_text())[
        "cameras"
    ]
    return cameras


def test_audit_without_a_rig_judges_the_cameras_from_tf_static() -> None:
    result = audit_log(THREE, jobs=1)
    truth = _truth(THREE)
    assert sorted(c.sync.camera for c in result.cameras) == sorted(truth)
    for cam in result.cameras:
        assert cam.sync.judged
        assert "/tf_static" in cam.azimuth_source and "driver default" in cam.azimuth_source
        assert cam.azimuth_deg == pytest.approx(truth[cam.sync.camera]["azimuth_deg"], abs=1e-6)
        ideal = truth[cam.sync.camera]["ideal_delay_mean_ns"]
        assert cam.sync.delay_recommended_ns == pytest.approx(ideal, abs=20_000)


@pytest.mark.parametrize(("model", "zero_deg"), [("VLP-32C", 180.0), ("PandarXT32", 95.0)])
def test_audit_without_a_rig_finds_where_the_triggers_fire(
    tmp_path: Path, model: LidarModel, zero_deg: float
) -> None:
    """No rig, so no zero azimuth: revolutions start at the triggers' packet azimuth (guessed
    once for the LiDAR, issue 23: no longer a warning per camera)."""
    out = tmp_path / "log.mcap"
    cameras = [CameraSim(name=f"cam{i}", yaw_deg=yaw) for i, yaw in enumerate((10, 100, 200, 300))]
    config = SyncSimConfig(
        duration_s=1.5, seed=71, lidar_model=model, zero_azimuth_deg=zero_deg, cameras=cameras
    )
    truth = simulate_sync_log(out, config)
    result = audit_log(out, jobs=1)
    assert len(result.cameras) == len(cameras)
    for cam in result.cameras:
        t = truth["cameras"][cam.sync.camera]
        # The tracker keys camera crossings to the rig's zero crossings: a camera crossing
        # before the log's first one is unknown, so the first frame may stay unpaired.
        assert cam.sync.frames_paired >= len(t["frames"]) - 1, cam.sync.unpaired
        assert cam.sync.delay_recommended_ns == pytest.approx(t["ideal_delay_mean_ns"], abs=20_000)
    (said,) = [g for g in result.guessed if g.startswith("lidar.zero_azimuth_deg")]
    fired = float(said.split("lidar.zero_azimuth_deg ")[1].split(" ")[0])
    assert fired == pytest.approx(result.rig.lidar.zero_azimuth_deg, abs=0.005)
    assert abs((fired - zero_deg + 180.0) % 360.0 - 180.0) < 5.0  # within a packet or so


def test_rig_zero_far_from_the_triggers_is_warned(tmp_path: Path) -> None:
    out = tmp_path / "log.mcap"
    truth = simulate_sync_log(out, SyncSimConfig(duration_s=1.0, seed=72, zero_azimuth_deg=200.0))
    rig = rig_from_truth(truth)
    wrong = rig.model_copy(
        update={"lidar": rig.lidar.model_copy(update={"zero_azimuth_deg": 20.0})}
    )
    audited = audit_log(out, wrong, jobs=1)
    warned = audited.warnings
    # Once, for the LiDAR (issue 23), not in each camera's list.
    assert sum("from the rig's zero_azimuth_deg 20" in w for w in warned) == 1
    assert not any("zero_azimuth_deg" in w for c in audited.cameras for w in c.sync.warnings)
    right = audit_log(out, rig, jobs=1)
    assert not any("zero_azimuth_deg" in w for w in right.warnings)


def test_vendor_x_axis_defaults() -> None:
    # The simulator places /tf_static by the same driver conventions (its own constants).
    for vendor, azimuth in SIMULATED_X_AXIS.items():
        assert X_AXIS_AZIMUTH_DEG[vendor] == azimuth
    assert x_axis_azimuth_deg(LidarConfig(topic="/p"), "ouster") == (
        180.0,
        "ouster ROS driver default",
    )
    assert (
        x_axis_azimuth_deg(LidarConfig(topic="/p", azimuth_of_x_axis_deg=12.0), "hesai")[0] == 12.0
    )
    assert x_axis_azimuth_deg(LidarConfig(topic="/p"), None) == (None, "unknown vendor")


def _topics(**types: str) -> dict[str, TopicInfo]:
    return {
        name: TopicInfo(name=name, msgtype=msgtype, encoding="cdr", count=10, has_definition=True)
        for name, msgtype in types.items()
    }


def test_trigger_event_topic_is_not_a_phantom_camera() -> None:
    topics = _topics(
        **{
            "/cam_front/image_raw": "sensor_msgs/msg/Image",
            "/cam_front/trigger_event": "syncaudit_msgs/msg/TriggerEvent",
            "/cam_front/exposure_status": "syncaudit_msgs/msg/CameraExposure",
            "/cam_rear/image_color": "sensor_msgs/msg/Image",
            "/sync/events": "syncaudit_msgs/msg/TriggerEvent",
        }
    )
    cameras = detect_cameras(
        topics,
        camera_fields={"/sync/events": "cam_rear"},
        frame_ids={"/cam_front/image_raw": "cam_front_optical"},
    )
    by_name = {c.name: c for c in cameras}
    assert sorted(by_name) == ["cam_front", "cam_rear"]
    assert by_name["cam_front"].trigger_topic == "/cam_front/trigger_event"
    assert by_name["cam_front"].exposure_topic == "/cam_front/exposure_status"
    assert by_name["cam_front"].frame_id == "cam_front_optical"
    assert by_name["cam_rear"].trigger_topic == "/sync/events"


@pytest.mark.parametrize(
    "name", ["vlp16_short.bag", "vlp16_short_ros2", "vlp16_three_cameras.mcap"]
)
def test_header_frame_id_from_raw_bytes(name: str) -> None:
    with open_log(SAMPLES / name) as log:
        msg = next(iter(log.messages(["/cameras/front/image_raw"])))
        assert header_frame_id(msg) == str(log.deserialize(msg).header.frame_id)  # type: ignore[attr-defined]


def test_header_frame_id_of_cut_bytes_is_empty() -> None:
    msg = RawMessage("/c/image_raw", "sensor_msgs/msg/Image", 0, b"\x00\x01\x00\x00\x01", "cdr")
    assert header_frame_id(msg) == ""


def test_starter_rig_is_a_valid_rig_one_edit_away(tmp_path: Path) -> None:
    text = starter_rig_yaml(THREE)
    assert "TODO" in text and "# azimuth_deg:" in text
    out = tmp_path / "rig.yaml"
    out.write_text(text)
    assert yaml.safe_load(text)["lidar"]["azimuth_of_x_axis_deg"] == 0
    rig = load_rig(out)
    assert [c.frame_id for c in rig.cameras] == [
        f"{n}_optical_frame" for n in sorted(_truth(THREE))
    ]
    result = audit_log(THREE, rig, jobs=1)
    for cam in result.cameras:
        ideal = _truth(THREE)[cam.sync.camera]["ideal_delay_mean_ns"]
        assert cam.sync.delay_recommended_ns == pytest.approx(ideal, abs=20_000)


def test_rig_command_writes_the_starter_rig(tmp_path: Path) -> None:
    out = tmp_path / "rig.yaml"
    runner = CliRunner()
    first = runner.invoke(app, ["rig", str(SAMPLES / "vlp16_short.bag"), "-o", str(out)])
    assert first.exit_code == 0, first.output
    assert load_rig(out).lidar.topic == "/velodyne_packets"
    again = runner.invoke(app, ["rig", str(SAMPLES / "vlp16_short.bag"), "-o", str(out)])
    assert again.exit_code == 8
    printed = runner.invoke(app, ["rig", str(SAMPLES / "vlp16_short.bag")])
    # The file carries the tool's mark (docs/outputs.md); what is printed is the rig itself.
    assert printed.exit_code == 0 and printed.output == out.read_text().removeprefix(COMMENT_MARK)
