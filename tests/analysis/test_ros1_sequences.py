"""ROS 1 header `seq` pairs frames with triggers only when it means something (issue 9, item 2).

`rosbags-convert` writes `seq = 0` into every header of a bag converted from ROS 2, and
some drivers never fill it. Sequence pairing then collapses every frame onto one trigger;
the audit must notice, pair by time, say why, and give the same numbers as the ROS 2 log.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.convert import convert

from syncaudit.analysis.pairing import pair_triggers, sequence_problem
from syncaudit.audit.run import audit_log
from syncaudit.columns.table import MISSING, Table, int_column
from syncaudit.logs import open_log
from syncaudit.simulate.rig_file import rig_from_truth
from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log
from syncaudit.writers.log_writer import writer_registry


def _numbers(result: Any) -> str:
    """Everything the audit says about the cameras and the LiDAR, without the file's name."""
    data = result.to_dict()
    for key in ("path", "container", "warnings"):
        data.pop(key)
    for cam in data["cameras"]:
        cam.pop("warnings")
    return json.dumps(data, sort_keys=True)


def test_converted_bag_with_zero_seq_gives_the_ros2_results(tmp_path: Path) -> None:
    # FLIR ImageMetaData carries no frame counter: in ROS 1 its frames are numbered by seq.
    cfg = SyncSimConfig(duration_s=1.5, seed=5, exposure_messages=("flir_meta",))
    truth = simulate_sync_log(tmp_path / "log.mcap", cfg)
    simulate_sync_log(tmp_path / "db3", cfg.model_copy(update={"log_format": "db3"}))
    bag = tmp_path / "converted.bag"
    # What `rosbags-convert --dst converted.bag db3` does, with the project's message types.
    convert(
        [tmp_path / "db3"],
        bag,
        None,
        None,
        None,
        "default",
        writer_registry(ros1=False).store,
        writer_registry(ros1=True).store,
        [],
        [],
        [],
        [],
    )
    with open_log(bag) as log:
        meta = next(iter(log.messages(["/cameras/front/meta"])))
        assert log.deserialize(meta).header.seq == 0  # the converter's seq, as in the issue
    rig = rig_from_truth(truth)
    results = {p: audit_log(tmp_path / p, rig, jobs=1) for p in ("log.mcap", "db3", bag.name)}
    converted = results[bag.name]
    for cam in converted.cameras:
        assert (
            cam.sync.frames_paired
            == cam.sync.frames_total
            == len(truth["cameras"]["front"]["frames"])
        )
        assert any("by time, not sequence number" in w for w in cam.sync.warnings)
        assert any("repeat" in w for w in cam.sync.warnings)
    assert _numbers(results["log.mcap"]) == _numbers(results["db3"]) == _numbers(converted)


def test_bag_whose_driver_leaves_seq_at_zero(tmp_path: Path) -> None:
    cfg = SyncSimConfig(duration_s=1.5, seed=6, exposure_messages=("flir_meta",))
    truth = simulate_sync_log(tmp_path / "log.mcap", cfg)
    bag = cfg.model_copy(update={"log_format": "bag", "ros1_header_seq": False})
    simulate_sync_log(tmp_path / "log.bag", bag)
    with open_log(tmp_path / "log.bag") as log:
        metas = list(log.messages(["/cameras/front/meta"]))
        assert {log.deserialize(m).header.seq for m in metas} == {0}  # type: ignore[attr-defined]
    rig = rig_from_truth(truth)
    reference = audit_log(tmp_path / "log.mcap", rig, jobs=1)
    zero_seq = audit_log(tmp_path / "log.bag", rig, jobs=1)
    assert all(c.sync.frames_paired == c.sync.frames_total > 0 for c in zero_seq.cameras)
    assert _numbers(reference) == _numbers(zero_seq)


def _frames(seq: list[int | None], start_ns: list[int]) -> Table:
    return Table(
        {
            "frame_sequence": int_column(seq),
            "header_stamp_ns": int_column(start_ns),
            "log_time_ns": int_column([s + 9_000_000 for s in start_ns]),
            "exposure_start_ns": int_column(start_ns),
        }
    )


def _triggers(seq: list[int | None], start_ns: list[int]) -> Table:
    return Table(
        {
            "frame_sequence": int_column(seq),
            "log_time_ns": int_column([s + 1_000 for s in start_ns]),
            "lidar_packet_ns": int_column([s - 20_000_000 for s in start_ns]),
            "exposure_start_ns": int_column(start_ns),
        }
    )


T0 = 1_700_000_000_123_456_789
STARTS = [T0 + 100_000_000 * i + 7 for i in range(5)]


@pytest.mark.parametrize(
    ("frame_seq", "trigger_seq", "problem"),
    [
        ([0, 1, 2, 3, 4], [0, 1, 2, 3, 4], None),
        ([0, 0, 0, 0, 0], [0, 1, 2, 3, 4], "frame sequence numbers repeat"),
        ([4, 3, 2, 1, 0], [4, 3, 2, 1, 0], "do not increase"),
        ([0, 1, 2, 3, None], [0, 1, 2, 3, 4], "1 of 5 frames have no sequence number"),
        ([10, 11, 12, 13, 14], [0, 1, 2, 3, 4], "no frame sequence number matches"),
        # Both count, but from different starts: seq pairing would be off by two frames.
        ([2, 3, 4, 5, 6], [0, 1, 2, 3, 4], "within 50 ms of their trigger"),
    ],
)
def test_sequence_problem(
    frame_seq: list[int | None], trigger_seq: list[int | None], problem: str | None
) -> None:
    found = sequence_problem(_frames(frame_seq, STARTS), _triggers(trigger_seq, STARTS))
    assert (found is None) if problem is None else (problem in str(found))


def test_unset_trigger_stamps_are_missing() -> None:
    triggers = _triggers(list(range(5)), STARTS)
    triggers["lidar_packet_ns"][1] = 0
    paired, _ = pair_triggers(_frames(list(range(5)), STARTS), triggers)
    missing = paired["trig_lidar_packet_ns"] == MISSING
    assert missing.tolist() == [False, True, False, False, False]


def test_time_pairing_keeps_exact_stamps() -> None:
    paired, warning = pair_triggers(_frames([0] * 5, STARTS), _triggers(list(range(5)), STARTS))
    assert warning is not None and "repeat" in warning
    assert paired["trig_lidar_packet_ns"].tolist() == [s - 20_000_000 for s in STARTS]
    assert paired["trig_lidar_packet_ns"].dtype == np.int64  # exact: never through float


def test_sequence_wrapping_at_2_32_falls_back_to_time_pairing() -> None:
    """ROS 1 header seq (and the uint32 frame_sequence fields) wrap after 2^32 messages:
    13.6 years of a 10 Hz publisher, so no log is expected to hold one. Should a counter
    start near the top, the numbers stop increasing and the frames pair by time, still each
    with its own trigger."""
    wrapping = [2**32 - 2, 2**32 - 1, 0, 1, 2]
    frames, triggers = _frames(wrapping, STARTS), _triggers(wrapping, STARTS)
    assert "do not increase" in str(sequence_problem(frames, triggers))
    paired, warning = pair_triggers(frames, triggers)
    assert warning is not None and "by time" in warning
    assert paired["trig_lidar_packet_ns"].tolist() == [s - 20_000_000 for s in STARTS]


def test_time_pairing_takes_a_trigger_recorded_just_after_the_derived_start() -> None:
    """A start derived from an exposure_end stamp minus a whole-microsecond exposure can lie
    up to 0.5 us before the trigger's own 248: it is still that frame's trigger."""
    early = [s - 400 for s in STARTS]
    paired, _ = pair_triggers(_frames([0] * 5, early), _triggers(list(range(5)), STARTS))
    assert paired["trig_lidar_packet_ns"].tolist() == [s - 20_000_000 for s in STARTS]
