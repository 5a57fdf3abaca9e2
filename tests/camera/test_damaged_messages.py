"""Damaged camera messages: read without raising, skipped with a counted warning.

A CameraExposure / TriggerEvent / ImageMetaData cut at any byte, an empty payload, an
Image of 7 bytes, bit flips in strings or in stamps: the struct readers and the header
reader say what is wrong instead of raising `struct.error` or `UnicodeDecodeError`, and
the table builder drops those rows with one warning per topic (LogReadError only where
a topic holds nothing readable).
"""

from __future__ import annotations

import struct
from pathlib import Path

import pytest
from mcap.records import Channel, Message, Schema

from mcap_copy import copy_mcap
from syncaudit.camera.cdr_fast import FAST_READERS, read_fast
from syncaudit.camera.extract import (
    CameraTableBuilder,
    exposure_row,
    header_frame_id,
    image_row,
    trigger_row,
)
from syncaudit.camera.rowstore import DamagedRow
from syncaudit.errors import LogReadError
from syncaudit.logs import RawMessage, open_log
from syncaudit.rig import CameraConfig, load_rig
from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log

SAMPLE = Path(__file__).resolve().parents[2] / "sample_logs" / "vlp16_three_cameras.mcap"


@pytest.fixture(scope="module")
def messages(tmp_path_factory: pytest.TempPathFactory) -> dict[str, RawMessage]:
    """One real message of each fast-read type, and one image, from a simulated log."""
    out = tmp_path_factory.mktemp("damaged") / "log.mcap"
    simulate_sync_log(out, SyncSimConfig(seed=82, duration_s=0.5))
    found: dict[str, RawMessage] = {}
    with open_log(out) as log:
        for msg in log.messages():
            if msg.msgtype not in found:
                found[msg.msgtype] = RawMessage(
                    msg.topic, msg.msgtype, msg.log_time_ns, bytes(msg.data), msg.encoding
                )
    return found


def _row(msg: RawMessage, fields: object) -> object:
    if msg.msgtype.endswith("TriggerEvent"):
        return trigger_row(msg, fields, "front")
    return exposure_row(msg, fields, "front", "exposure_start")


@pytest.mark.parametrize("msgtype", sorted(FAST_READERS))
def test_every_cut_is_damaged_not_an_exception(
    messages: dict[str, RawMessage], msgtype: str
) -> None:
    whole = messages[msgtype]
    expected = _row(whole, read_fast(whole.data, msgtype, "cdr"))
    assert not isinstance(expected, DamagedRow)
    readable = []
    for cut in range(len(whole.data)):
        msg = RawMessage(whole.topic, msgtype, whole.log_time_ns, whole.data[:cut], "cdr")
        fields = read_fast(msg.data, msgtype, "cdr")
        assert fields is not None
        row = _row(msg, fields)
        if not isinstance(row, DamagedRow):
            # Only fields after the last one the audit reads may be cut (ImageMetaData).
            assert row == expected
            readable.append(cut)
            continue
        assert row.topic == whole.topic
        assert row.log_time_ns == whole.log_time_ns
        assert str(len(msg.data)) in row.reason
    assert not readable or min(readable) >= 40


def test_reasons_name_the_type_and_the_field(messages: dict[str, RawMessage]) -> None:
    data = messages["syncaudit_msgs/msg/CameraExposure"].data
    assert read_fast(b"", "syncaudit_msgs/msg/CameraExposure", "cdr").damaged == (
        "CameraExposure of 0 bytes has no CDR encapsulation header (nothing)"
    )
    cut = read_fast(data[:7], "syncaudit_msgs/msg/CameraExposure", "cdr")
    assert cut.damaged == (
        "truncated CameraExposure (7 bytes): a 4-byte field at byte 4 is missing or cut"
    )
    hostile = bytearray(data)
    hostile[12:16] = (2**31).to_bytes(4, "little")  # frame_id length past the end
    assert (
        "a string of 2147483648 bytes at byte 12"
        in read_fast(bytes(hostile), "syncaudit_msgs/msg/CameraExposure", "cdr").damaged
    )


def test_bit_flips_in_strings_decode_leniently(messages: dict[str, RawMessage]) -> None:
    msg = messages["syncaudit_msgs/msg/TriggerEvent"]
    data = bytearray(msg.data)
    frame_id_at = 16  # encapsulation 4 + stamp 8 + length 4
    data[frame_id_at] ^= 0x80  # an invalid UTF-8 start byte
    fields = read_fast(bytes(data), msg.msgtype, "cdr")
    assert "\ufffd" in fields.header.frame_id
    flipped = trigger_row(msg, fields, "front")
    intact = trigger_row(msg, read_fast(msg.data, msg.msgtype, "cdr"), "front")
    assert isinstance(flipped, tuple) and isinstance(intact, tuple)
    # Only the frame_id (last column) differs: on a shared topic that message would name
    # no camera of the rig and be left out with a warning, never given to another camera.
    assert flipped[:-1] == intact[:-1]
    assert "\ufffd" in flipped[-1] and intact[-1] == "front_optical_frame"


def test_nan_durations_and_negative_stamps_are_damaged(messages: dict[str, RawMessage]) -> None:
    msg = messages["syncaudit_msgs/msg/CameraExposure"]
    fields = read_fast(msg.data, msg.msgtype, "cdr")
    fields.exposure_duration = float("nan")
    assert "exposure_duration nan s is not a duration" in _row(msg, fields).reason
    fields = read_fast(msg.data, msg.msgtype, "cdr")
    fields.exposure_start.sec = -5
    assert "out of range" in _row(msg, fields).reason


def test_images_too_short_for_a_stamp(messages: dict[str, RawMessage]) -> None:
    image = messages["sensor_msgs/msg/Image"]
    assert isinstance(image_row(image), tuple)
    for cut in (0, 7, 11):
        msg = RawMessage(image.topic, image.msgtype, 5, image.data[:cut], "cdr")
        row = image_row(msg)
        assert isinstance(row, DamagedRow)
        assert row.reason == f"{cut} bytes cannot hold a header stamp"
    ros1 = RawMessage(image.topic, image.msgtype, 5, b"\x01\x00\x00", "ros1")
    assert isinstance(image_row(ros1), DamagedRow)


def test_builder_skips_damaged_rows_with_one_warning_per_topic(
    messages: dict[str, RawMessage],
) -> None:
    cam = CameraConfig(name="front", image_topic="/img", exposure_topic="/exp")
    image = messages["sensor_msgs/msg/Image"]
    good = image_row(image)
    builder = CameraTableBuilder(cam)
    builder.images.extend([good, DamagedRow("/img", 2_000_000_000, "7 bytes"), good])
    builder.images.append(DamagedRow("/img", 3_000_000_000, "0 bytes"))
    tables = builder.build()
    assert len(tables.images) == 2
    assert tables.warnings == (
        "camera front: 2 damaged messages skipped on /img "
        "(first at log time 2.000000000 s: 7 bytes)",
    )
    builder = CameraTableBuilder(cam)
    builder.images.append(DamagedRow("/img", 2_000_000_000, "7 bytes"))
    with pytest.raises(LogReadError, match="camera front: all 1 messages on /img are damaged"):
        builder.build()


def test_audit_of_a_log_with_cut_exposures_goes_on(tmp_path: Path) -> None:
    """End to end: every third CameraExposure of one camera cut to 7 bytes."""
    from syncaudit.audit.run import audit_log

    src = SAMPLE
    dst = tmp_path / "cut.mcap"
    cuts: list[int] = []

    def every_third_front_exposure(_schema: Schema, channel: Channel, message: Message) -> bytes:
        if channel.topic == "/cameras/front/exposure" and message.sequence % 3 == 0:
            cuts.append(message.log_time)
            return message.data[:7]
        return message.data

    copy_mcap(src, dst, change=every_third_front_exposure)
    cut = len(cuts)
    assert cut > 5
    rig = load_rig(Path(f"{SAMPLE}.rig.yaml"))
    whole = audit_log(src, rig, jobs=1)
    damaged = audit_log(dst, rig, jobs=1)
    (line,) = [w for w in damaged.warnings if "damaged" in w]
    assert line.startswith(
        f"camera front: {cut} damaged messages skipped on /cameras/front/exposure (first at"
    )
    assert "truncated CameraExposure (7 bytes)" in line
    assert [c.sync.camera for c in damaged.cameras] == ["front", "rear_left", "rear_right"]
    front, whole_front = damaged.cameras[0].sync, whole.cameras[0].sync
    assert len(front.frames) == len(whole_front.frames) - cut
    # The other cameras are audited exactly as on the whole log.
    assert damaged.cameras[1].to_dict() == whole.cameras[1].to_dict()


def test_only_cdr_le_and_be_are_read(messages: dict[str, RawMessage]) -> None:
    """PL_CDR (00 02/00 03) is a parameter list, not the plain layout ROS 2 writes: the
    struct readers and the image header reader refuse it as they refuse any other id
    (they used to read 00 03 as CDR_LE and 00 02 as CDR_BE)."""
    for head in (b"\x00\x02", b"\x00\x03", b"\x00\x07"):
        for msgtype in FAST_READERS:
            data = head + messages[msgtype].data[2:]
            name = msgtype.rsplit("/", 1)[-1]
            assert read_fast(data, msgtype, "cdr").damaged == (
                f"{name} of {len(data)} bytes has no CDR encapsulation header ({data[:4].hex()})"
            )
        image = messages["sensor_msgs/msg/Image"]
        bad = RawMessage(image.topic, image.msgtype, 5, head + image.data[2:], "cdr")
        row = image_row(bad)
        assert isinstance(row, DamagedRow) and "encapsulation" in row.reason
        assert header_frame_id(bad) == ""
    assert header_frame_id(messages["sensor_msgs/msg/Image"]) == "front_optical_frame"


def test_a_cdr_string_without_its_nul_is_damaged(messages: dict[str, RawMessage]) -> None:
    """CDR strings end in a NUL their length counts; one whose last byte is not NUL has a
    wrong length: damaged (it used to be read with its last character dropped)."""
    msg = messages["syncaudit_msgs/msg/CameraExposure"]
    data = bytearray(msg.data)
    (length,) = struct.unpack_from("<I", data, 12)
    data[16 + length - 1] = ord("x")
    fields = read_fast(bytes(data), msg.msgtype, "cdr")
    assert fields.damaged == (
        f"damaged CameraExposure ({len(data)} bytes): "
        f"a string of {length} bytes at byte 12 has no NUL"
    )
    image = messages["sensor_msgs/msg/Image"]
    cut_nul = bytearray(image.data)
    cut_nul[16 + struct.unpack_from("<I", cut_nul, 12)[0] - 1] = ord("x")
    row = image_row(RawMessage(image.topic, image.msgtype, 5, bytes(cut_nul), "cdr"))
    assert isinstance(row, tuple) and row[3] == ""  # the stamp is read, the name is not
