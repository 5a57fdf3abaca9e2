"""Pairing frames with triggers by ROS 1 header.seq where cameras share a topic.

roscpp and rospy number `header.seq` per publisher: on a topic one driver node publishes
for several cameras, seq counts every camera's messages, so one camera's frames carry
every third number. Such numbers pair only with numbers counting the same messages (the
header.seq of a trigger topic the same cameras share); against a camera's own counter
(`TriggerEvent.frame_sequence`, a per-camera topic's seq) the frames pair by time, and the
result says which method was used and why.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import syncaudit.analysis.sync as sync_module
from syncaudit.analysis.pairing import (
    BY_SEQUENCE,
    BY_TIME,
    NO_TRIGGERS,
    TriggerPairing,
    incomparable,
    pair_frames,
    sequence_problem,
)
from syncaudit.audit.run import AuditResult, audit_log
from syncaudit.camera.sequences import field_counter, header_seq_counter
from syncaudit.columns.table import Table, int_column
from syncaudit.simulate.rig_file import rig_from_truth
from syncaudit.simulate.sync_log import CameraSim, SyncSimConfig, simulate_sync_log

CAMERAS = [
    CameraSim(name="front", yaw_deg=0.0, delay_error_us=300.0),
    CameraSim(name="left", yaw_deg=100.0, delay_error_us=-500.0),
    CameraSim(name="rear", yaw_deg=200.0),
]
NAMES = ("front", "left", "rear")


def _audit(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, log_format: str = "bag", **config: Any
) -> tuple[AuditResult, dict[str, Any], dict[str, TriggerPairing]]:
    """Audit a simulated log; also returns each camera's trigger pairing as the audit made it."""
    out = tmp_path / f"log.{log_format}"
    cfg = SyncSimConfig(
        cameras=CAMERAS,
        duration_s=2.0,
        seed=21,
        log_format=log_format,
        exposure_messages=("flir_meta",),
        **config,
    )
    truth = simulate_sync_log(out, cfg)
    pairings: list[TriggerPairing] = []

    def recording(*args: Any, **kwargs: Any) -> TriggerPairing:
        pairing = pair_frames(*args, **kwargs)
        pairings.append(pairing)
        return pairing

    monkeypatch.setattr(sync_module, "pair_frames", recording)
    result = audit_log(out, rig_from_truth(truth), jobs=1)
    return result, truth, dict(zip([c.sync.camera for c in result.cameras], pairings, strict=True))


def _assert_own_triggers(
    result: AuditResult, truth: dict[str, Any], pairings: dict[str, TriggerPairing]
) -> None:
    """Every frame paired with the trigger of its own exposure (checkpoint 246 of the truth)."""
    for cam in result.cameras:
        frames = truth["cameras"][cam.sync.camera]["frames"]
        sent = [
            f["lidar_packet_ns"] + f["t1_ns"] + f["t2_ns"] + f["applied_delay_ns"] + f["t3_ns"]
            for f in frames
        ]
        paired = pairings[cam.sync.camera].frames
        assert len(paired) == len(frames)
        assert paired["trig_camera_sensor_ns"].tolist() == sent, cam.sync.camera
        assert cam.sync.frames_paired == len(frames)


def _pairing_warnings(result: AuditResult, name: str) -> list[str]:
    sync = next(c.sync for c in result.cameras if c.sync.camera == name)
    return [w for w in sync.warnings if "paired with triggers" in w]


def test_shared_topics_numbered_by_one_driver_pair_by_sequence(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Metadata and triggers both on topics the three cameras share: both header.seq count
    the same messages (one driver publishing each frame on each topic), so seq pairs them."""
    result, truth, pairings = _audit(
        tmp_path,
        monkeypatch,
        shared_topics=("meta", "trigger"),
        trigger_message="time_reference",
        camera_field=False,
    )
    seq = pairings["front"].frames["frame_sequence"].tolist()
    assert seq[:3] != [0, 1, 2] and np.all(np.diff(seq) >= 2)  # every camera's messages counted
    for name in NAMES:
        assert pairings[name].method == BY_SEQUENCE
        assert _pairing_warnings(result, name) == []
    assert {c.to_dict()["trigger_pairing"] for c in (x.sync for x in result.cameras)} == {
        "sequence number"
    }
    _assert_own_triggers(result, truth, pairings)


@pytest.mark.parametrize(
    ("trigger_message", "shared", "trigger_counter"),
    [
        # The triggers' own frame counter against the shared topic's seq.
        ("trigger_event", ("meta",), "TriggerEvent.frame_sequence"),
        ("trigger_event", ("meta", "trigger"), "TriggerEvent.frame_sequence"),
        # Each camera's trigger topic numbered by its own publisher.
        ("time_reference", ("meta",), "header.seq of /cameras/front/trigger"),
    ],
)
def test_shared_seq_against_a_camera_counter_pairs_by_time(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    trigger_message: str,
    shared: tuple[str, ...],
    trigger_counter: str,
) -> None:
    result, truth, pairings = _audit(
        tmp_path, monkeypatch, shared_topics=shared, trigger_message=trigger_message
    )
    for name in NAMES:
        assert pairings[name].method == BY_TIME
        reason = pairings[name].reason or ""
        assert "header.seq of /cameras/meta (shared by cameras front, left, rear" in reason
        assert trigger_counter.replace("front", name) in reason
        assert _pairing_warnings(result, name) == [
            f"frames paired with triggers by time, not sequence number: {reason}"
        ]
    assert {c.sync.trigger_pairing for c in result.cameras} == {"time"}
    _assert_own_triggers(result, truth, pairings)
    if trigger_message == "trigger_event":  # the whole chain: t1..t4 of each frame's own
        for cam in result.cameras:
            frames = truth["cameras"][cam.sync.camera]["frames"]
            for t in ("t1_ns", "t2_ns", "t3_ns", "t4_ns"):
                got = cam.sync.frames[t].to_numpy(np.float64)
                assert np.array_equal(got, [float(f[t]) for f in frames]), (cam.sync.camera, t)


def test_one_topic_per_camera_still_pairs_by_sequence(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    result, truth, pairings = _audit(tmp_path, monkeypatch, trigger_message="time_reference")
    assert {p.method for p in pairings.values()} == {BY_SEQUENCE}
    _assert_own_triggers(result, truth, pairings)


@pytest.mark.parametrize(
    ("log_format", "ros1_header_seq", "reason", "warned"),
    [
        # seq = 0 everywhere (converted bags, some drivers): repeats, whatever the sharing.
        ("bag", False, "frame sequence numbers repeat (1 distinct", True),
        # ROS 2 headers have no seq: time is the only way, and nothing to warn about.
        ("mcap", True, "no sequence number", False),
    ],
)
def test_shared_topics_without_usable_seq_pair_by_time(
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    log_format: str,
    ros1_header_seq: bool,
    reason: str,
    warned: bool,
) -> None:
    result, truth, pairings = _audit(
        tmp_path,
        monkeypatch,
        log_format=log_format,
        shared_topics=("meta", "trigger"),
        trigger_message="time_reference",
        ros1_header_seq=ros1_header_seq,
    )
    for name, pairing in pairings.items():
        assert pairing.method == BY_TIME and reason in (pairing.reason or "")
        assert len(_pairing_warnings(result, name)) == int(warned)
    _assert_own_triggers(result, truth, pairings)


def test_without_triggers_the_method_is_none(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    result, _, pairings = _audit(tmp_path, monkeypatch, trigger_messages=False)
    assert {p.method for p in pairings.values()} == {NO_TRIGGERS}
    assert {c.sync.trigger_pairing for c in result.cameras} == {"none"}


def test_counters_alike_only_when_they_count_the_same_messages() -> None:
    shared_meta = header_seq_counter("/cameras/meta", ("left", "front"))
    shared_trigger = header_seq_counter("/cameras/trigger", ("front", "left"))
    assert incomparable(shared_meta, shared_trigger) is None
    own = header_seq_counter("/cameras/front/meta", ("front",))
    assert incomparable(own, field_counter("syncaudit_msgs/msg/TriggerEvent", "front")) is None
    why = incomparable(shared_meta, field_counter("syncaudit_msgs/msg/TriggerEvent", "front"))
    assert why is not None and "shared by cameras front, left" in why
    # The same topic shared by other cameras than the trigger topic: different counts.
    other = header_seq_counter("/cameras/trigger", ("front", "left", "rear"))
    assert incomparable(shared_meta, other) is not None


T0 = 1_700_000_000_000_000_000


def test_shared_topics_published_in_another_order_fail_the_time_check() -> None:
    """Two topics of the same cameras whose driver publishes them in different orders: the
    numbers are alike in kind, but pair frames with other cameras' triggers; time decides."""
    starts = [T0 + 100_000_000 * i for i in range(6)]
    frames = Table(
        {
            "frame_sequence": int_column([0, 2, 4, 6, 8, 10]),
            "header_stamp_ns": int_column(starts),
            "log_time_ns": int_column([s + 9_000_000 for s in starts]),
            "exposure_start_ns": int_column(starts),
        }
    )
    triggers = Table(
        {
            "frame_sequence": int_column([1, 3, 5, 7, 9, 11]),
            "log_time_ns": int_column(starts),
            "exposure_start_ns": int_column(starts),
        }
    )
    counters = (
        header_seq_counter("/cams/meta", ("a", "b")),
        header_seq_counter("/cams/trigger", ("a", "b")),
    )
    assert "no frame sequence number matches" in str(sequence_problem(frames, triggers, counters))
    pairing = pair_frames(frames, triggers, counters=counters)
    assert pairing.method == BY_TIME
    assert pairing.frames["trig_exposure_start_ns"].tolist() == starts


def test_console_and_html_say_how_frames_were_paired(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from syncaudit.cli import app

    out = tmp_path / "log.bag"
    cfg = SyncSimConfig(
        cameras=CAMERAS[:1],
        duration_s=2.5,  # 20 frames or more: the camera is judged, its table shown
        seed=3,
        log_format="bag",
        exposure_messages=("flir_meta",),
        trigger_message="time_reference",
    )
    simulate_sync_log(out, cfg)
    rig = tmp_path / "rig.json"
    rig.write_text(
        rig_from_truth(json.loads(Path(f"{out}.truth.json").read_text())).model_dump_json()
    )
    html = tmp_path / "report.html"
    result = CliRunner().invoke(app, ["audit", str(out), "--rig", str(rig), "--html", str(html)])
    assert result.exit_code == 0, result.output
    assert re.search(r"frames paired with triggers by[\s│]+sequence number", result.stdout)
    assert re.search(
        r"frames paired with triggers by</th><td[^>]*>sequence number</td>", html.read_text()
    )
