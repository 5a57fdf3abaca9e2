"""The struct reader of tf2_msgs/TFMessage gives rosbags' frames and rotations, in CDR of
either byte order (every string padding) and ROS 1, and None for bytes that do not fit;
the camera mounts of /tf_static are then read without the log's type registry."""

from __future__ import annotations

import itertools
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from syncaudit.camera.azimuth import tf_static_yaws
from syncaudit.camera.cdr_fast import read_tf_message
from syncaudit.logs import open_log

REPO = Path(__file__).resolve().parents[2]
SAMPLES = [
    REPO / "sample_logs" / "vlp16_three_cameras.mcap",
    REPO / "sample_logs" / "pandar40p_adaptive.mcap",
    REPO / "sample_logs" / "vlp16_short.bag",
]


def _fields(tf: Any) -> list[tuple[object, ...]]:
    return [
        (
            t.header.frame_id,
            t.child_frame_id,
            t.transform.translation.x,
            t.transform.translation.y,
            t.transform.translation.z,
            t.transform.rotation.x,
            t.transform.rotation.y,
            t.transform.rotation.z,
            t.transform.rotation.w,
        )
        for t in tf.transforms
    ]


@pytest.mark.parametrize("path", SAMPLES, ids=lambda p: p.name)
def test_tf_static_of_the_sample_logs_as_rosbags_reads_it(path: Path) -> None:
    with open_log(path) as log:
        topics = [t.name for t in log.topics.values() if t.msgtype == "tf2_msgs/msg/TFMessage"]
        messages = list(log.messages(topics))
        assert messages
        for msg in messages:
            fast = read_tf_message(msg.data, msg.encoding)
            assert fast is not None and fast.transforms
            assert _fields(fast) == _fields(log.deserialize(msg))


@pytest.mark.parametrize("path", SAMPLES, ids=lambda p: p.name)
def test_tf_static_yaws_need_no_type_registry(path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with open_log(path) as log:
        expected = tf_static_yaws(log)
    assert expected

    def no_registry(self: Any, encoding: str) -> None:
        raise AssertionError("a type registry was built")

    with open_log(path) as log:
        monkeypatch.setattr(type(log), "type_registry", no_registry)
        assert tf_static_yaws(log) == expected


def _tf_message(path: Path, encoding: str) -> tuple[Any, Any, str]:
    """(rosbags' first TFMessage of `path`, the typestore of `encoding`, the type name)."""
    with open_log(path) as log:
        topics = [t.name for t in log.topics.values() if t.msgtype == "tf2_msgs/msg/TFMessage"]
        msg = next(iter(log.messages(topics)))
        return log.deserialize(msg), log.type_registry(encoding).store, msg.msgtype


def _variants(original: Any) -> list[Any]:
    """The message with 1-4 character frame names (every padding) and one or two transforms."""
    first = original.transforms[0]
    out = []
    for frame_len, child_len, count in itertools.product(range(1, 5), range(1, 5), (1, 2)):
        one = replace(
            first,
            header=replace(first.header, frame_id="f" * frame_len),
            child_frame_id="c" * child_len,
        )
        out.append(replace(original, transforms=[one] * count))
    return out


def test_every_padding_both_byte_orders_and_every_cut() -> None:
    original, store, msgtype = _tf_message(SAMPLES[0], "cdr")
    for changed in _variants(original):
        for little in (True, False):
            data = bytes(store.serialize_cdr(changed, msgtype, little_endian=little))
            fast = read_tf_message(data, "cdr")
            assert fast is not None and _fields(fast) == _fields(changed)
            assert all(read_tf_message(data[:cut], "cdr") is None for cut in range(len(data)))
    original, store, msgtype = _tf_message(SAMPLES[2], "ros1")
    for changed in _variants(original):
        data = bytes(store.serialize_ros1(changed, msgtype))
        fast = read_tf_message(data, "ros1")
        assert fast is not None and _fields(fast) == _fields(changed)
        assert all(read_tf_message(data[:cut], "ros1") is None for cut in range(len(data)))
    assert read_tf_message(b"\x00\x01\x00\x00\xff\xff\xff\xff", "cdr") is None  # huge count
    assert read_tf_message(b"\x00" * 64, "protobuf") is None


def test_random_damage_never_raises() -> None:
    """Flipped bytes (counts, lengths, strings) give a namespace or None, never an error."""
    import random

    rng = random.Random(7)
    for path, encoding in ((SAMPLES[0], "cdr"), (SAMPLES[2], "ros1")):
        original, store, msgtype = _tf_message(path, encoding)
        data = bytes(
            store.serialize_cdr(original, msgtype)
            if encoding == "cdr"
            else store.serialize_ros1(original, msgtype)
        )
        for _ in range(2000):
            mutant = bytearray(data)
            for _ in range(rng.randint(1, 4)):
                mutant[rng.randrange(len(mutant))] = rng.randrange(256)
            got = read_tf_message(bytes(mutant[: rng.randint(0, len(mutant))]), encoding)
            assert got is None or isinstance(got.transforms, list)


def test_only_cdr_le_and_be_are_read() -> None:
    """PL_CDR and XCDR2 bodies are not the plain layout: None, and rosbags is asked."""
    original, store, msgtype = _tf_message(SAMPLES[0], "cdr")
    data = bytes(store.serialize_cdr(original, msgtype))
    assert read_tf_message(data, "cdr") is not None
    for head in (b"\x00\x02", b"\x00\x03", b"\x00\x07"):
        assert read_tf_message(head + data[2:], "cdr") is None
