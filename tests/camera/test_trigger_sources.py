"""Trigger rows from TIER IV's builtin_interfaces/Time topics and sensor_msgs/TimeReference."""

from __future__ import annotations

from rosbags.typesys import Stores, get_typestore

from syncaudit.camera.extract import trigger_row
from syncaudit.logs import RawMessage, TypeRegistry

STORE = get_typestore(Stores.ROS2_HUMBLE)
TIME = STORE.types["builtin_interfaces/msg/Time"]


def _raw(msg: object, msgtype: str) -> RawMessage:
    return RawMessage("/t", msgtype, 5, STORE.serialize_cdr(msg, msgtype), "cdr")


def test_time_and_time_reference_give_checkpoint_246() -> None:
    registry = TypeRegistry(ros1=False)
    stamp = TIME(sec=1_700_000_000, nanosec=123_456_789)
    as_time = _raw(stamp, "builtin_interfaces/msg/Time")
    header = STORE.types["std_msgs/msg/Header"](stamp=TIME(sec=1, nanosec=2), frame_id="cam")
    ref = STORE.types["sensor_msgs/msg/TimeReference"](header=header, time_ref=stamp, source="t")
    as_ref = _raw(ref, "sensor_msgs/msg/TimeReference")
    for raw in (as_time, as_ref):
        msg = registry.deserialize(raw.data, raw.msgtype, raw.encoding)
        row = trigger_row(raw, msg, "front")
        # (camera, seq, log time, 240, 242, 244, 246, 248, applied delay, source)
        assert row[0] == "front" and row[2] == 5
        assert row[6] == 1_700_000_000_123_456_789
        assert row[3:6] == (None, None, None) and row[7:9] == (None, None)
        assert row[9] == raw.msgtype


def test_ros1_sequence_of_a_time_reference_but_not_of_a_bare_time() -> None:
    """ROS 1 header.seq leads a TimeReference; a bare Time has no header: its first four
    bytes are the seconds, not a sequence number."""
    registry = TypeRegistry(ros1=True)
    stamp = TIME(sec=1_700_000_000, nanosec=5)
    header = STORE.types["std_msgs/msg/Header"](stamp=stamp, frame_id="cam")
    ref = STORE.types["sensor_msgs/msg/TimeReference"](header=header, time_ref=stamp, source="")
    for msg, msgtype, seq in (
        (stamp, "builtin_interfaces/msg/Time", None),
        (ref, "sensor_msgs/msg/TimeReference", 0),
    ):
        data = STORE.cdr_to_ros1(STORE.serialize_cdr(msg, msgtype), msgtype)  # seq 0 in ROS 1
        raw = RawMessage("/t", msgtype, 5, data, "ros1")
        row = trigger_row(raw, registry.deserialize(raw.data, msgtype, "ros1"), "front")
        assert row[1] == seq and row[6] == 1_700_000_000_000_000_005
