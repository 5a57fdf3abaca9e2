"""Simulated sync logs: contents as configured, packets decode to the truth, exact truth."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from syncaudit.analysis.controller import ControllerConfig, DelayController, FrameObservation
from syncaudit.cli.simulate_controller import ControllerDelays
from syncaudit.errors import ConfigError, OutputError
from syncaudit.lidar.hesai import decode_hesai, pandar_scan_packets
from syncaudit.lidar.packets import PacketTiming
from syncaudit.lidar.velodyne import decode_velodyne, velodyne_scan_packets
from syncaudit.logs import LogReader, open_log
from syncaudit.simulate.delays import CONSTANT_WINDOW_FRAMES
from syncaudit.simulate.sync_log import (
    CameraSim,
    LatencyDist,
    LidarModel,
    LightModel,
    SyncSimConfig,
    simulate_sync_log,
    truth_path,
)
from syncaudit.writers.provenance import WRITTEN_BY

SHORT_S = 2.5


def _frames(truth: dict[str, Any], camera: str) -> dict[str, NDArray[np.int64]]:
    """Per-frame truth of one camera as int64 columns."""
    rows = truth["cameras"][camera]["frames"]
    return {k: np.array([r[k] for r in rows], dtype=np.int64) for k in rows[0]}


def _decode_lidar(log: LogReader, truth: dict[str, Any]) -> tuple[PacketTiming, NDArray[np.int64]]:
    """All packets of the LiDAR topic through the vendor decoders, with driver stamps."""
    lidar = truth["lidar"]
    stamps, datas, sizes, log_times, last_stamps = [], [], [], [], []
    for raw in log.messages([lidar["topic"]]):
        if lidar["vendor"] == "velodyne":
            s, d = velodyne_scan_packets(raw.data, raw.encoding)
            size = np.full(s.size, d.shape[1], dtype=np.uint32)
        else:
            s, d, size = pandar_scan_packets(raw.data, raw.encoding)
        stamps.append(s)
        datas.append(np.array(d))
        sizes.append(np.array(size))
        log_times.append(raw.log_time_ns)
        last_stamps.append(int(s[-1]))
    # Each scan is logged when its last packet reached the driver.
    assert log_times == last_stamps
    driver = np.concatenate(stamps)
    data = np.concatenate(datas)
    if lidar["vendor"] == "velodyne":
        return decode_velodyne(data, driver), driver
    return decode_hesai(data, np.concatenate(sizes), driver), driver


@pytest.fixture(scope="module")
def velodyne_log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    out = tmp_path_factory.mktemp("sim") / "vlp16.mcap"
    config = SyncSimConfig(
        seed=7,
        lidar_model="VLP-16",
        clock_offset_ns=1_531 * 1_000_000_000,
        packet_drop_fraction=0.02,
        cameras=[
            CameraSim(name="front", yaw_deg=0.0, delay_error_us=1_500.0),
            CameraSim(name="left", yaw_deg=90.0, stamp_semantics="exposure_middle"),
            CameraSim(name="rear", yaw_deg=180.0, stamp_semantics="trigger"),
        ],
        duration_s=SHORT_S,
    )
    return out, simulate_sync_log(out, config)


def test_topics_types_counts(velodyne_log: tuple[Path, dict[str, Any]]) -> None:
    out, truth = velodyne_log
    saved = json.loads(truth_path(out).read_text())
    assert saved.pop("written_by") == WRITTEN_BY  # the tool's mark, first key
    assert saved == json.loads(json.dumps(truth))
    with open_log(out) as log:
        topics = {name: (info.msgtype, info.count) for name, info in log.topics.items()}
    revolutions = truth["lidar"]["revolutions"]
    expected: dict[str, tuple[str, int]] = {
        "/tf_static": ("tf2_msgs/msg/TFMessage", 1),
        "/velodyne_packets": ("velodyne_msgs/msg/VelodyneScan", revolutions),
    }
    for name, cam in truth["cameras"].items():
        assert cam["frames_count"] == revolutions - 1
        prefix = f"/cameras/{name}"
        assert cam["topics"] == {
            "image": f"{prefix}/image_raw",
            "exposure": f"{prefix}/exposure",
            "meta": f"{prefix}/meta",
            "trigger": f"{prefix}/trigger",
        }
        n = cam["frames_count"]
        expected[f"{prefix}/image_raw"] = ("sensor_msgs/msg/Image", n)
        expected[f"{prefix}/exposure"] = ("syncaudit_msgs/msg/CameraExposure", n)
        expected[f"{prefix}/meta"] = ("flir_camera_msgs/msg/ImageMetaData", n)
        expected[f"{prefix}/trigger"] = ("syncaudit_msgs/msg/TriggerEvent", n)
    assert topics == expected
    assert revolutions >= 24  # 2.5 s at 600 RPM


def test_optional_messages(tmp_path: Path) -> None:
    config = SyncSimConfig(
        lidar_model="PandarXT32",
        image_kind="compressed",
        exposure_messages=("flir_meta",),
        trigger_messages=False,
        cameras=[CameraSim(name="cam0", yaw_deg=45.0)],
        duration_s=1.0,
    )
    out = tmp_path / "x.mcap"
    truth = simulate_sync_log(out, config)
    with open_log(out) as log:
        assert set(log.topics) == {
            "/tf_static",
            "/pandar_packets",
            "/cameras/cam0/image_raw/compressed",
            "/cameras/cam0/meta",
        }
        images = [log.deserialize(m) for m in log.messages(["/cameras/cam0/image_raw/compressed"])]
    assert len(images) == truth["cameras"]["cam0"]["frames_count"]
    first: Any = images[0]
    assert first.format == "mono8; png compressed"
    assert bytes(first.data[:8]) == b"\x89PNG\r\n\x1a\n"


def test_packets_decode_to_truth(velodyne_log: tuple[Path, dict[str, Any]]) -> None:
    out, truth = velodyne_log
    lidar = truth["lidar"]
    with open_log(out) as log:
        timing, driver = _decode_lidar(log, truth)
    assert timing.model == "VLP-16"
    assert timing.n_packets == lidar["packets_written"]
    offset = lidar["clock_offset_ns"]
    capture = timing.sensor_time_ns - offset
    t1 = driver - capture
    assert t1.min() >= 150_000  # the configured floor of t1
    assert t1.mean() == pytest.approx(lidar["t1_mean_ns"])
    # Drops: gaps in the packet cadence are exactly the packets the truth says were lost.
    missing = np.rint(np.diff(timing.sensor_time_ns) / lidar["packet_period_ns"]) - 1
    assert int(missing.sum()) == lidar["packets_dropped"] > 0
    # The zero-crossing packet of each revolution: first block at/after the zero azimuth.
    units = 100
    az_q = np.rint(timing.block_azimuth_deg * units).astype(np.int64).reshape(-1)
    step = np.diff(az_q) % (360 * units)
    unwrapped = np.concatenate(([az_q[0]], az_q[0] + np.cumsum(step)))
    zero_q = round(lidar["zero_azimuth_deg"] * units)
    first_turn = (unwrapped[0] - zero_q) // (360 * units) + 1
    targets = zero_q + 360 * units * (first_turn + np.arange(lidar["revolutions"]))
    at = np.searchsorted(unwrapped, targets) // timing.block_azimuth_deg.shape[1]
    np.testing.assert_array_equal(capture[at], lidar["zero_packet_ns"])
    # Interpolating the packets' azimuths gives the truth's beam times within the 0.01 deg
    # quantisation (2.8 us of rotation at 600 RPM).
    block_t = (timing.block_time_ns - offset).reshape(-1).astype(np.float64)
    cross = np.interp(targets.astype(np.float64), unwrapped.astype(np.float64), block_t)
    assert np.abs(cross - np.array(lidar["zero_crossing_ns"])).max() < 3_000
    for cam in truth["cameras"].values():
        f = _frames(truth, cam["name"])
        angle = targets[: f["t_estimated_ns"].size] + round(cam["theta_deg"] * units)
        est = np.interp(angle.astype(np.float64), unwrapped.astype(np.float64), block_t)
        assert np.abs(est - f["t_estimated_ns"]).max() < 3_000
        np.testing.assert_array_equal(f["lidar_packet_ns"], lidar["zero_packet_ns"][:-1])


def test_truth_is_self_consistent(velodyne_log: tuple[Path, dict[str, Any]]) -> None:
    _, truth = velodyne_log
    for cam in truth["cameras"].values():
        f = _frames(truth, cam["name"])
        t5 = f["exposure_duration_ns"]
        assert (t5 % 2 == 0).all()
        chain = f["lidar_packet_ns"] + f["t1_ns"] + f["t2_ns"] + f["t3_ns"] + f["t4_ns"]
        np.testing.assert_array_equal(f["exposure_start_ns"], chain + f["applied_delay_ns"])
        np.testing.assert_array_equal(f["t_l_ns"], f["exposure_start_ns"] + t5 // 2)
        np.testing.assert_array_equal(f["error_ns"], f["t_l_ns"] - f["t_estimated_ns"])
        np.testing.assert_array_equal(f["ideal_delay_ns"], f["t_estimated_ns"] - chain - t5 // 2)
        np.testing.assert_array_equal(f["error_ns"], f["applied_delay_ns"] - f["ideal_delay_ns"])
        np.testing.assert_array_equal(
            f["packet_phase_ns"], f["zero_crossing_ns"] - f["lidar_packet_ns"]
        )
        abs_err = np.abs(f["error_ns"]).astype(np.float64)
        n = abs_err.size
        assert cam["error_mean_ns"] == pytest.approx(abs_err.mean(), rel=1e-12)
        eq6 = (np.sum(abs_err**2) / n - abs_err.mean() ** 2) * n / (n - 1)
        assert cam["error_var_ns2"] == pytest.approx(eq6, rel=1e-9)
        assert cam["error_var_ns2"] == pytest.approx(np.var(abs_err, ddof=1), rel=1e-9)
        assert cam["ideal_delay_mean_ns"] == pytest.approx(f["ideal_delay_ns"].mean())
        assert cam["ideal_delay_ns"] == round(f["ideal_delay_ns"].mean())
        for k in ("t1", "t2", "t3", "t4"):
            assert cam[f"{k}_mean_ns"] == pytest.approx(f[f"{k}_ns"].mean())
        # Controller off: a constant delay, off from the ideal by the configured error.
        delay = cam["applied_delay"]
        assert delay["mode"] == "constant"
        assert (f["applied_delay_ns"] == delay["initial_ns"]).all()
        assert delay["initial_ns"] == cam["ideal_delay_ns"] + delay["delay_error_ns"]
        # Eq. 1 with the mean rate, and theta from the zero azimuth in the rotation direction.
        omega = truth["lidar"]["omega_mean_deg_s"]
        assert cam["t_rotate_ns"] == round(cam["theta_deg"] / omega * 1e9)
        zero = truth["lidar"]["zero_azimuth_deg"]
        assert cam["theta_deg"] == pytest.approx((cam["azimuth_deg"] - zero) % 360.0)
    front = truth["cameras"]["front"]
    assert front["applied_delay"]["delay_error_ns"] == 1_500_000
    assert front["error_signed_mean_ns"] == pytest.approx(1_500_000, abs=1)


def _time(t: Any) -> int:
    return int(t.sec) * 1_000_000_000 + int(t.nanosec)


def test_camera_messages_carry_the_truth(velodyne_log: tuple[Path, dict[str, Any]]) -> None:
    out, truth = velodyne_log
    with open_log(out) as log:
        for cam in truth["cameras"].values():
            f = _frames(truth, cam["name"])
            topics = cam["topics"]
            triggers: list[Any] = [log.deserialize(m) for m in log.messages([topics["trigger"]])]
            exposures: list[Any] = [log.deserialize(m) for m in log.messages([topics["exposure"]])]
            metas: list[Any] = [log.deserialize(m) for m in log.messages([topics["meta"]])]
            images = list(log.messages([topics["image"]]))
            seq = [t.frame_sequence for t in triggers]
            assert seq == [e.frame_sequence for e in exposures] == f["frame_sequence"].tolist()
            packet = np.array([_time(t.lidar_packet_time) for t in triggers])
            driver = np.array([_time(t.lidar_driver_time) for t in triggers])
            cam_driver = np.array([_time(t.camera_driver_time) for t in triggers])
            cam_sensor = np.array([_time(t.camera_sensor_time) for t in triggers])
            start = np.array([_time(t.exposure_start_time) for t in triggers])
            applied = np.array([round(t.applied_delay * 1e9) for t in triggers])
            np.testing.assert_array_equal(packet, f["lidar_packet_ns"])
            np.testing.assert_array_equal(driver - packet, f["t1_ns"])
            np.testing.assert_array_equal(cam_driver - driver, f["t2_ns"])
            np.testing.assert_array_equal(cam_sensor - cam_driver - applied, f["t3_ns"])
            np.testing.assert_array_equal(start - cam_sensor, f["t4_ns"])
            np.testing.assert_array_equal(applied, f["applied_delay_ns"])
            np.testing.assert_array_equal(start, f["exposure_start_ns"])
            duration = np.array([round(e.exposure_duration * 1e9) for e in exposures])
            np.testing.assert_array_equal(duration, f["exposure_duration_ns"])
            ex_start = np.array([_time(e.exposure_start) for e in exposures])
            np.testing.assert_array_equal(ex_start, f["exposure_start_ns"])
            # The FLIR metadata holds whole microseconds (rounded).
            meta_us = np.array([m.exposure_time for m in metas])
            np.testing.assert_array_equal(meta_us, np.rint(f["exposure_duration_ns"] / 1e3))
            image_stamps = [_time(log.deserialize(m).header.stamp) for m in images]  # type: ignore[attr-defined]
            expected = {
                "exposure_start": f["exposure_start_ns"],
                "exposure_middle": f["exposure_start_ns"] + f["exposure_duration_ns"] // 2,
                "exposure_end": f["exposure_start_ns"] + f["exposure_duration_ns"],
                "trigger": cam_sensor,
            }[cam["stamp_semantics"]]
            np.testing.assert_array_equal(image_stamps, expected)
            np.testing.assert_array_equal(image_stamps, f["image_stamp_ns"])
            log_times = np.array([m.log_time_ns for m in images])
            np.testing.assert_array_equal(log_times, f["image_log_time_ns"])
            assert (log_times > f["exposure_start_ns"] + f["exposure_duration_ns"]).all()


def test_tf_static_yaws(velodyne_log: tuple[Path, dict[str, Any]]) -> None:
    out, truth = velodyne_log
    with open_log(out) as log:
        (raw,) = list(log.messages(["/tf_static"]))
        tf: Any = log.deserialize(raw)
    assert len(tf.transforms) == len(truth["cameras"])
    for transform in tf.transforms:
        cam = next(
            c for c in truth["cameras"].values() if c["frame_id"] == transform.child_frame_id
        )
        assert transform.header.frame_id == truth["config"]["lidar_frame"]
        q = transform.transform.rotation
        x, y, z, w = q.x, q.y, q.z, q.w
        # Optical +Z axis rotated into the LiDAR frame.
        forward = (2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y))
        yaw = np.degrees(np.arctan2(forward[1], forward[0]))
        assert (yaw - cam["yaw_deg"] + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-9)
        assert forward[2] == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("model", ["VLP-32C", "Pandar40P", "PandarXT32"])
def test_other_models_decode(tmp_path: Path, model: LidarModel) -> None:
    out = tmp_path / "m.mcap"
    truth = simulate_sync_log(
        out, SyncSimConfig(lidar_model=model, duration_s=1.0, packet_drop_fraction=0.0)
    )
    with open_log(out) as log:
        timing, driver = _decode_lidar(log, truth)
    lidar = truth["lidar"]
    assert timing.model == model
    assert timing.n_packets == lidar["packets_written"]
    assert lidar["packets_dropped"] == 0
    period = np.diff(timing.sensor_time_ns)
    assert np.abs(period - lidar["packet_period_ns"]).max() < 1_000
    # Rate from the decoded trajectory within the drift of the nominal.
    az = np.unwrap(np.radians(timing.block_azimuth_deg.reshape(-1)))
    t = timing.block_time_ns.reshape(-1).astype(np.float64)
    rpm = np.polyfit(t / 1e9, np.degrees(az), 1)[0] / 6.0
    assert rpm == pytest.approx(600.0, rel=0.006)
    assert np.all(driver - timing.sensor_time_ns > 0)


def _plain(value: Any) -> Any:
    """A message as nested builtins, without ROS 1's header sequence number."""
    if hasattr(value, "__msgtype__"):
        return {
            k: _plain(getattr(value, k))
            for k in value.__dataclass_fields__
            if not (k == "seq" and value.__msgtype__ == "std_msgs/msg/Header")
        }
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, list):
        return [_plain(v) for v in value]
    return value


def test_three_formats_hold_the_same_messages(tmp_path: Path) -> None:
    base = {"seed": 3, "lidar_model": "PandarXT32", "duration_s": 1.0}
    paths = {"mcap": tmp_path / "a.mcap", "db3": tmp_path / "b", "bag": tmp_path / "c.bag"}
    truths = {
        fmt: simulate_sync_log(path, SyncSimConfig(log_format=fmt, **base))  # type: ignore[arg-type]
        for fmt, path in paths.items()
    }
    for truth in truths.values():
        assert truth["cameras"] == truths["mcap"]["cameras"]
        assert truth["lidar"] == truths["mcap"]["lidar"]
    contents: dict[str, dict[str, list[tuple[int, Any]]]] = {}
    raw_bytes: dict[str, dict[str, list[bytes]]] = {}
    for fmt, path in paths.items():
        with open_log(path) as log:
            contents[fmt] = {}
            raw_bytes[fmt] = {}
            for msg in log.messages():
                value = log.deserialize(msg)
                contents[fmt].setdefault(msg.topic, []).append((msg.log_time_ns, _plain(value)))
                raw_bytes[fmt].setdefault(msg.topic, []).append(bytes(msg.data))
    assert contents["mcap"] == contents["db3"] == contents["bag"]
    assert raw_bytes["mcap"] == raw_bytes["db3"]  # both CDR
    # The ROS 1 bag numbers frames in header.seq like a ROS 1 publisher.
    with open_log(paths["bag"]) as log:
        seqs = [log.deserialize(m).header.seq for m in log.messages(["/cameras/front/image_raw"])]  # type: ignore[attr-defined]
    assert seqs == list(range(len(seqs)))


def test_deterministic_from_seed(tmp_path: Path) -> None:
    config = SyncSimConfig(seed=11, duration_s=1.0)
    a = simulate_sync_log(tmp_path / "a.mcap", config)
    b = simulate_sync_log(tmp_path / "b.mcap", config)
    c = simulate_sync_log(tmp_path / "c.mcap", config.model_copy(update={"seed": 12}))
    assert a["cameras"] == b["cameras"]
    assert a["cameras"] != c["cameras"]
    assert (tmp_path / "a.mcap").read_bytes() == (tmp_path / "b.mcap").read_bytes()


def test_controller_runs_live(tmp_path: Path) -> None:
    controller = ControllerConfig(mode="shift", window_frames=5, min_frames=5)
    config = SyncSimConfig(
        lidar_model="PandarXT32",
        duration_s=4.0,
        light=LightModel(tunnel_start_s=100.0),
        cameras=[CameraSim(name="front", yaw_deg=0.0, delay_error_us=4_000.0)],
    )
    truth = simulate_sync_log(tmp_path / "c.mcap", config, delays=ControllerDelays(controller))
    cam = truth["cameras"]["front"]
    f = _frames(truth, "front")
    assert cam["applied_delay"]["mode"] == "controller"
    assert cam["applied_delay"]["adjustments"]
    assert truth["config"]["controller"] == controller.model_dump(mode="json")
    assert cam["t5_window_frames"] == 5
    # Replaying the observations through a fresh controller gives the same delays.
    replay = DelayController(controller, initial_delay_ns=int(f["applied_delay_ns"][0]))
    delays = [int(f["applied_delay_ns"][0])]
    omega_nominal = 600 * 6 / 1e9
    zero = np.array(truth["lidar"]["zero_crossing_ns"], dtype=np.float64)
    for i in range(f["frame_sequence"].size - 1):
        omega = omega_nominal if i == 0 else 360.0 / (zero[i] - zero[i - 1])
        obs = FrameObservation(
            int(f["t1_ns"][i]),
            int(f["t2_ns"][i]),
            int(f["t3_ns"][i]),
            int(f["t4_ns"][i]),
            int(f["exposure_duration_ns"][i]),
            int(f["error_ns"][i]),
            round(cam["theta_deg"] / omega),
        )
        delays.append(replay.update(obs))
    np.testing.assert_array_equal(f["applied_delay_ns"], delays)
    first = np.abs(f["error_ns"][:5]).mean()
    last = np.abs(f["error_ns"][-10:]).mean()
    assert first > 3_000_000
    assert last < 500_000


def test_constant_delays_name_the_controllers_default_window(tmp_path: Path) -> None:
    """Without a controller the truth still names the t5 window: the controller's default."""
    assert ControllerConfig().window_frames == CONSTANT_WINDOW_FRAMES
    truth = simulate_sync_log(tmp_path / "k.mcap", SyncSimConfig(duration_s=0.5))
    cam = truth["cameras"]["front"]
    assert cam["t5_window_frames"] == CONSTANT_WINDOW_FRAMES
    assert cam["applied_delay"]["mode"] == "constant"
    assert truth["config"]["controller"] is None
    assert set(cam["applied_delay"]) >= {"initial_ns", "final_ns"}
    assert cam["applied_delay"]["min_ns"] == cam["applied_delay"]["max_ns"]


def test_latency_distribution() -> None:
    rng = np.random.default_rng(0)
    values = LatencyDist(mean_us=300.0, std_us=40.0, min_us=150.0).draw_ns(rng, 200_000)
    assert values.min() >= 150_000
    assert values.mean() == pytest.approx(300_000, rel=0.005)
    assert values.std() == pytest.approx(40_000, rel=0.03)
    constant = LatencyDist(mean_us=50.0).draw_ns(rng, 3)
    assert constant.tolist() == [50_000, 50_000, 50_000]


def test_outputs_not_clobbered(tmp_path: Path) -> None:
    out = tmp_path / "x.mcap"
    config = SyncSimConfig(duration_s=0.6)
    simulate_sync_log(out, config)
    before = out.read_bytes(), truth_path(out).read_bytes()
    with pytest.raises(OutputError, match="exists"):
        simulate_sync_log(out, config.model_copy(update={"seed": 5}))
    assert (out.read_bytes(), truth_path(out).read_bytes()) == before
    simulate_sync_log(out, config.model_copy(update={"seed": 5, "overwrite": True}))
    assert out.read_bytes() != before[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.mcap", "x.mcap.truth.json"]


def test_config_validation() -> None:
    with pytest.raises(ConfigError, match="unique"):
        SyncSimConfig(cameras=[CameraSim(name="a", yaw_deg=0), CameraSim(name="a", yaw_deg=9)])
    with pytest.raises(ConfigError):
        LatencyDist(mean_us=10.0, min_us=20.0)
    with pytest.raises(ConfigError):
        SyncSimConfig(lidar_model="HDL-64E")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("model", "convention", "offset"),
    [("VLP-16", "first_after", 0), ("Pandar40P", "containing", 2), ("VLP-32C", "containing", -2)],
)
def test_trigger_packet_conventions_name_real_packets(
    tmp_path: Path, model: str, convention: str, offset: int
) -> None:
    """Each TriggerEvent names a packet in the log, chosen by the convention from the
    decoded azimuths alone (an independent check of the simulator's choice)."""
    out = tmp_path / "log.mcap"
    config = SyncSimConfig(
        duration_s=1.0,
        seed=9,
        lidar_model=model,  # type: ignore[arg-type]
        trigger_packet=convention,  # type: ignore[arg-type]
        trigger_packet_offset=offset,
        packet_drop_fraction=0.02,
    )
    truth = simulate_sync_log(out, config)
    with open_log(out) as log:
        timing, _ = _decode_lidar(log, truth)
    stamps = timing.sensor_time_ns  # synchronised clock: sensor time = host time
    zero = truth["lidar"]["zero_azimuth_deg"]
    # Unwrapped angle past the zero azimuth of every block, in turns.
    rel = (timing.block_azimuth_deg - zero) % 360.0
    turn = np.cumsum(np.concatenate(([0], np.diff(rel[:, 0]) < -180.0)))
    first_block = rel[:, 0] / 360.0 + turn
    frames = _frames(truth, "front")
    named = np.searchsorted(stamps, frames["lidar_packet_ns"])
    assert np.array_equal(stamps[named], frames["lidar_packet_ns"])  # a packet of the log
    for row in named.tolist():
        # The packet the convention picks for this crossing, from the decoded azimuths.
        crossing = np.floor(first_block[row] + 0.5)  # the nearest crossing's turn
        containing = int(np.searchsorted(first_block, crossing, side="left"))
        if convention == "containing" and rel[containing - 1, -1] < 180.0:
            containing -= 1  # the crossing falls inside the previous packet
        expected = containing + offset
        assert row == expected


def test_sync_sim_config_reads_the_names_users_write() -> None:
    from syncaudit.errors import ConfigError
    from syncaudit.simulate.sync_log import lidar_model, sync_sim_config

    assert [lidar_model(n) for n in ("XT32", "xt32", "vlp16", "VLP-32C", "pandar40p")] == [
        "PandarXT32",
        "PandarXT32",
        "VLP-16",
        "VLP-32C",
        "Pandar40P",
    ]
    with pytest.raises(ConfigError, match="HDL-99"):
        lidar_model("HDL-99")
    config = sync_sim_config(lidar="XT32", tunnel=False, delay_error_us=150.0, duration_s=2.0)
    assert config.lidar_model == "PandarXT32" and config.duration_s == 2.0
    assert config.light.dark_exposure_us == config.light.bright_exposure_us
    assert {c.delay_error_us for c in config.cameras} == {150.0}
    with pytest.raises(ConfigError, match="duration_s"):
        sync_sim_config(duration_s=float("inf"))
