"""The struct readers give exactly what rosbags gives, on every per-frame message of a log
(ROS 2 CDR and ROS 1 serialization)."""

from __future__ import annotations

import itertools
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from syncaudit.camera import cdr_fast
from syncaudit.camera.cdr_fast import FAST_READERS, _Cursor, read_fast
from syncaudit.camera.extract import exposure_row, trigger_row
from syncaudit.logs import open_log
from syncaudit.logs.wire import WireError
from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log


@pytest.fixture(scope="module", params=["mcap", "mcap-ros1", "bag"])
def log_path(tmp_path_factory: pytest.TempPathFactory, request: pytest.FixtureRequest) -> Path:
    suffix = ".bag" if request.param == "bag" else ".mcap"
    out = tmp_path_factory.mktemp("fast") / f"log{suffix}"
    simulate_sync_log(out, SyncSimConfig(seed=81, duration_s=1.0, log_format=request.param))
    return out


def test_fast_rows_equal_rosbags_rows(log_path: Path) -> None:
    checked = dict.fromkeys(FAST_READERS, 0)
    with open_log(log_path) as log:
        topics = [t.name for t in log.topics.values() if t.msgtype in FAST_READERS]
        for msg in log.messages(topics):
            fast = read_fast(msg.data, msg.msgtype, msg.encoding)
            slow = log.deserialize(msg)
            assert fast is not None
            if msg.msgtype == "syncaudit_msgs/msg/TriggerEvent":
                assert trigger_row(msg, fast, "c") == trigger_row(msg, slow, "c")
            else:
                for semantics in ("exposure_start", "exposure_middle", "exposure_end"):
                    assert exposure_row(msg, fast, "c", semantics) == exposure_row(
                        msg, slow, "c", semantics
                    )
            checked[msg.msgtype] += 1
    assert all(count >= 20 for count in checked.values()), checked


def test_no_fast_path_for_other_types_or_encodings() -> None:
    assert read_fast(b"\x00" * 64, "syncaudit_msgs/msg/CameraExposure", "protobuf") is None
    assert read_fast(b"\x00\x01\x00\x00" + b"\x00" * 60, "sensor_msgs/msg/Image", "cdr") is None


def _plain(value: object) -> object:
    """A namespace as nested dicts (namespaces compare by identity of nested ones)."""
    if hasattr(value, "__dict__"):
        return {k: _plain(v) for k, v in vars(value).items()}
    return value


def test_ros1_one_pass_readers_equal_the_cursor_on_whole_and_cut_messages(
    tmp_path: Path,
) -> None:
    """The one-unpack ROS 1 readers give the cursor's fields, and on every truncation the
    cursor's own `damaged` text (they fall back to it)."""
    out = tmp_path / "log.bag"
    simulate_sync_log(out, SyncSimConfig(seed=5, duration_s=0.3, log_format="bag"))
    checked = dict.fromkeys(FAST_READERS, 0)
    with open_log(out) as log:
        topics = [t.name for t in log.topics.values() if t.msgtype in FAST_READERS]
        for msg in log.messages(topics):
            data = bytes(msg.data)
            for cut in (len(data), *range(0, len(data), 3)):
                part = data[:cut]
                try:
                    expected = FAST_READERS[msg.msgtype](_Cursor(part, ros1=True))
                except WireError:
                    got = read_fast(part, msg.msgtype, "ros1")
                    assert got is not None and got.damaged.startswith("truncated ")
                    continue
                assert _plain(read_fast(part, msg.msgtype, "ros1")) == _plain(expected)
            checked[msg.msgtype] += 1
    assert all(count >= 3 for count in checked.values()), checked


def _picked(message: object, like: object) -> object:
    """The fields of a rosbags message that the namespace `like` holds, as nested dicts."""
    if hasattr(like, "__dict__"):
        return {k: _picked(getattr(message, k), v) for k, v in vars(like).items()}
    return message


def _cdr_variants(tmp_path: Path) -> list[tuple[str, bytes, object]]:
    """Every per-frame message of a simulated ROS 2 log, re-serialised with rosbags in both
    byte orders and with names of 1-4 characters (every padding before the fields after a
    string), as (msgtype, CDR bytes, rosbags' message)."""
    out = tmp_path / "log.mcap"
    simulate_sync_log(out, SyncSimConfig(seed=9, duration_s=0.3, log_format="mcap"))
    variants: list[tuple[str, bytes, object]] = []
    with open_log(out) as log:
        store = log.type_registry("cdr").store
        topics = [t.name for t in log.topics.values() if t.msgtype in FAST_READERS]
        for msg in log.messages(topics):
            original: Any = log.deserialize(msg)
            for camera_len, frame_len in itertools.product(range(1, 5), range(1, 5)):
                header = replace(original.header, frame_id="f" * frame_len)
                changed = replace(original, header=header)
                if hasattr(changed, "camera"):
                    changed = replace(changed, camera="c" * camera_len)
                for little in (True, False):
                    data = bytes(store.serialize_cdr(changed, msg.msgtype, little_endian=little))
                    variants.append((msg.msgtype, data, changed))
    return variants


def test_cdr_one_pass_readers_equal_rosbags_and_the_cursor(tmp_path: Path) -> None:
    """The one-pass CDR readers give rosbags' fields in both byte orders and every string
    padding, and on every truncation the cursor's own `damaged` text (they fall back)."""
    checked: dict[tuple[str, bool], int] = {}
    for msgtype, data, reference in _cdr_variants(tmp_path):
        with pytest.MonkeyPatch.context() as patch:  # a whole message never falls back
            patch.setattr(cdr_fast, "_Cursor", None)
            fast = read_fast(data, msgtype, "cdr")
        assert fast is not None and not hasattr(fast, "damaged")
        assert _plain(fast) == _plain(FAST_READERS[msgtype](_Cursor(data)))
        assert _plain(fast) == _picked(reference, fast)  # and what rosbags decoded
        little = data[1] == 1
        checked[(msgtype, little)] = checked.get((msgtype, little), 0) + 1
        for cut in range(4, len(data), 3):
            part = data[:cut]
            got = read_fast(part, msgtype, "cdr")
            assert got is not None
            try:
                expected = FAST_READERS[msgtype](_Cursor(part))
            except WireError:
                assert got.damaged.startswith("truncated ")
                continue
            assert _plain(got) == _plain(expected)
    assert len(checked) == 2 * len(FAST_READERS), checked
    assert all(count >= 3 * 16 for count in checked.values()), checked
