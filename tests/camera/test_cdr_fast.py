"""The struct readers give exactly what rosbags gives, on every per-frame message of a log
(ROS 2 CDR and ROS 1 serialization)."""

from __future__ import annotations

from pathlib import Path

import pytest

from syncaudit.camera.cdr_fast import FAST_READERS, _Cursor, _TruncatedError, read_fast
from syncaudit.camera.extract import exposure_row, trigger_row
from syncaudit.logs import open_log
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
                except _TruncatedError:
                    got = read_fast(part, msg.msgtype, "ros1")
                    assert got is not None and got.damaged.startswith("truncated ")
                    continue
                assert _plain(read_fast(part, msg.msgtype, "ros1")) == _plain(expected)
            checked[msg.msgtype] += 1
    assert all(count >= 3 for count in checked.values()), checked
