"""Issue 10 items 3 (audit side), 12 and 13, each on a real mutant of a sample log.

- 3: a camera topic whose message encoding is not cdr/ros1 is dropped with a warning; the
  LiDAR topic in one is UnknownTypeError (exit 4), never the decoder's ValueError.
- 12: `lidar.vendor` contradicting the packets is a ConfigError naming the key.
- 13: `info` fails on the LiDAR topic exactly as `audit` does (same error class), and
  with `partial=True` still returns everything it could read.
"""

from __future__ import annotations

import struct
from pathlib import Path

import mutators as mu
import pytest

from syncaudit.audit.inspect import inspect_log
from syncaudit.audit.run import audit_log
from syncaudit.errors import ConfigError, DecodeError, SyncauditError, UnknownTypeError
from syncaudit.lidar.stream import decode_scan
from syncaudit.logs import RawMessage, open_log
from syncaudit.rig import Rig, load_rig

SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"
VLP16 = SAMPLES / "vlp16_three_cameras.mcap"
LIDAR = "/velodyne_packets"


@pytest.fixture(scope="module")
def rig() -> Rig:
    return load_rig(Path(f"{VLP16}.rig.yaml"))


def _with_encoding(tmp_path: Path, topic: str, encoding: str) -> Path:
    out = tmp_path / f"enc-{encoding or 'none'}.mcap"
    mu.rewrite_mcap(VLP16, out, encoding_of=lambda t, _m, e: encoding if t == topic else e)
    return out


@pytest.mark.parametrize("encoding", ["protobuf", "json", "cdr2", ""])
def test_camera_topic_in_another_encoding_is_skipped(
    tmp_path: Path, rig: Rig, encoding: str
) -> None:
    log = _with_encoding(tmp_path, "/cameras/front/exposure", encoding)
    result = audit_log(log, rig, jobs=1)
    shown = repr(encoding) if encoding else "no encoding"
    assert (
        f"camera front: /cameras/front/exposure: message encoding {shown} is not ROS "
        "(cdr/ros1); syncaudit cannot read it; topic skipped"
    ) in result.warnings
    assert "camera front: no exposure metadata" in result.missing
    assert [c.sync.camera for c in result.cameras] == ["front", "rear_left", "rear_right"]


@pytest.mark.parametrize("encoding", ["protobuf", "", "cdr2"])
def test_lidar_topic_in_another_encoding_is_exit_4(tmp_path: Path, rig: Rig, encoding: str) -> None:
    log = _with_encoding(tmp_path, LIDAR, encoding)
    with pytest.raises(UnknownTypeError, match="LiDAR topic /velodyne_packets: message encoding"):
        audit_log(log, rig, jobs=1)
    with pytest.raises(UnknownTypeError):  # guessed rig, and info, say the same
        audit_log(log, jobs=1)
    with pytest.raises(UnknownTypeError):
        inspect_log(log)


def test_decoder_entry_raises_unknown_type_not_value_error() -> None:
    with open_log(VLP16) as log:
        msg = next(iter(log.messages([LIDAR])))
    odd = RawMessage(msg.topic, msg.msgtype, msg.log_time_ns, bytes(msg.data), "protobuf")
    with pytest.raises(UnknownTypeError, match="'protobuf' is not ROS"):
        decode_scan("velodyne", odd, 0)
    assert issubclass(UnknownTypeError, SyncauditError)


@pytest.mark.parametrize("vendor", ["hesai", "ouster"])
def test_rig_vendor_contradicting_the_packets_is_exit_6(rig: Rig, vendor: str) -> None:
    wrong = rig.model_copy(update={"lidar": rig.lidar.model_copy(update={"vendor": vendor})})
    message = (
        f"lidar.vendor: the rig says '{vendor}' but /velodyne_packets carries velodyne "
        "packets (velodyne_msgs/msg/VelodyneScan); fix or remove the key"
    )
    with pytest.raises(ConfigError) as caught:
        audit_log(VLP16, wrong, jobs=1)
    assert str(caught.value) == message
    assert ConfigError.exit_code == 6
    with pytest.raises(ConfigError):
        inspect_log(VLP16, wrong)
    right = rig.model_copy(update={"lidar": rig.lidar.model_copy(update={"vendor": "velodyne"})})
    assert len(audit_log(VLP16, right, jobs=1).cameras) == 3


def _damaged_lidar(tmp_path: Path) -> Path:
    """Every VelodyneScan's first packet gets an impossible block flag (DecodeError)."""
    out = tmp_path / "bad-lidar.mcap"

    def payload_of(topic: str, _m: str, _i: int, data: bytes) -> bytes:
        if topic != LIDAR:
            return data
        raw = bytearray(data)
        # CDR: header stamp 8, frame_id string, then the packet sequence; corrupt its
        # length so that it claims far more packets than the message holds.
        (frame_len,) = struct.unpack_from("<I", raw, 12)
        at = 16 + frame_len
        at += -at % 4
        struct.pack_into("<I", raw, at, 2**31)
        return bytes(raw)

    mu.rewrite_mcap(VLP16, out, payload_of=payload_of)
    return out


def test_info_and_audit_agree_on_a_damaged_lidar(tmp_path: Path, rig: Rig) -> None:
    log = _damaged_lidar(tmp_path)
    with pytest.raises(SyncauditError) as by_audit:
        audit_log(log, rig, jobs=1)
    with pytest.raises(SyncauditError) as by_info:
        inspect_log(log, rig)
    assert type(by_info.value) is type(by_audit.value)
    assert isinstance(by_audit.value, DecodeError | SyncauditError)
    assert by_audit.value.exit_code in (3, 5)
    report = inspect_log(log, rig, partial=True)
    assert report.exit_code == by_audit.value.exit_code
    assert report.error == str(by_info.value)
    assert LIDAR in {t.name for t in report.topics}
    assert len(report.cameras) == 3
    assert not any("no LiDAR packet topic found" in w for w in report.warnings)
    assert report.to_dict()["exit_code"] == report.exit_code
    # Without a rig (LiDAR guessed by type), the same.
    with pytest.raises(type(by_audit.value)):
        inspect_log(log)


def test_a_rig_of_thousands_of_cameras_is_refused_at_once(rig: Rig) -> None:
    """Item 9: past MAX_CAMERAS the rig is a ConfigError before any message is read."""
    import time

    from syncaudit.audit.rig_check import MAX_CAMERAS

    cams = [
        rig.cameras[i % 3].model_copy(update={"name": f"cam{i}"}) for i in range(MAX_CAMERAS + 1)
    ]
    many = rig.model_copy(update={"cameras": cams})
    start = time.process_time()  # CPU time: the work done, not the machine's load
    with pytest.raises(ConfigError, match=f"cameras: the rig lists {MAX_CAMERAS + 1} cameras"):
        audit_log(VLP16, many, jobs=1)
    assert time.process_time() - start < 5.0


def test_info_command_prints_what_it_read_then_exits_as_audit(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from syncaudit.cli import app

    log = _damaged_lidar(tmp_path)
    runner = CliRunner()
    audited = runner.invoke(app, ["audit", str(log), "--rig", f"{VLP16}.rig.yaml"])
    shown = runner.invoke(app, ["info", str(log), "--rig", f"{VLP16}.rig.yaml"])
    assert audited.exit_code in (3, 5)
    assert shown.exit_code == audited.exit_code, shown.output
    assert LIDAR in shown.stdout and "/cameras/front" in shown.stdout  # the table is printed
    assert shown.stderr.startswith("error: ") and shown.stderr.count("\n") == 1
    assert "Traceback" not in shown.output
