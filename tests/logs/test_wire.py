"""The ROS 1 / CDR wire readers: accepted encapsulations, headers and strings, damage."""

from __future__ import annotations

import struct

import pytest

from syncaudit.errors import DecodeError
from syncaudit.logs.wire import (
    WireError,
    cdr_align,
    cdr_byte_order,
    cdr_header,
    cdr_string,
    cdr_time,
    ros1_header,
    ros1_string,
    ros1_time,
)


def _cdr_header_bytes(order: str, sec: int, nsec: int, frame_id: bytes) -> bytes:
    encapsulation = b"\x00\x01" if order == "<" else b"\x00\x00"
    text = frame_id + b"\0"
    return encapsulation + b"\0\0" + struct.pack(order + "iII", sec, nsec, len(text)) + text


@pytest.mark.parametrize(("head", "order"), [(b"\x00\x00", ">"), (b"\x00\x01", "<")])
def test_cdr_le_and_be_are_accepted(head: bytes, order: str) -> None:
    assert cdr_byte_order(head + b"\x00\x00") == order
    assert cdr_byte_order(memoryview(head + b"\x00\x03")) == order  # options are not read


@pytest.mark.parametrize(
    "head",
    [
        b"\x00\x02",  # PL_CDR_BE: a parameter list, not the plain layout
        b"\x00\x03",  # PL_CDR_LE
        b"\x00\x06",  # CDR2_BE: XCDR2 aligns 8-byte fields to 4
        b"\x00\x07",  # CDR2_LE
        b"\x00\x0b",  # PL_CDR2_LE
        b"\x01\x00",
        b"\xff\xff",
    ],
)
def test_other_encapsulations_are_refused(head: bytes) -> None:
    with pytest.raises(WireError, match=f"encapsulation {head.hex()}0000 ") as exc:
        cdr_byte_order(head + b"\x00\x00" + b"\x00" * 12)
    assert not exc.value.cut
    assert isinstance(exc.value, DecodeError)


@pytest.mark.parametrize("size", range(4))
def test_too_short_for_an_encapsulation(size: int) -> None:
    with pytest.raises(WireError) as exc:
        cdr_byte_order(b"\x00\x01\x00"[:size])
    assert exc.value.cut and "\n" not in str(exc.value)


@pytest.mark.parametrize("order", "<>")
@pytest.mark.parametrize("length", range(0, 9))
def test_cdr_header_and_the_aligned_string_after_it(order: str, length: int) -> None:
    name = b"abcdefgh"[:length]
    data = _cdr_header_bytes(order, -3, 999_999_999, name)
    end = len(data)
    data += b"\xaa" * (cdr_align(end, 4) - end) + struct.pack(order + "I", 4) + b"cam\0"
    sec, nsec, frame_id, pos = cdr_header(data, 4, order)
    assert (sec, nsec, frame_id, pos) == (-3, 999_999_999, name.decode(), end)
    assert cdr_string(data, pos, order) == ("cam", len(data))
    assert cdr_time(data, 4, order) == (-3, 999_999_999, 12)
    assert cdr_string(data, 12, order) == (name.decode(), end)


def test_cdr_alignment_counts_from_after_the_encapsulation() -> None:
    assert [cdr_align(p, 4) for p in range(4, 10)] == [4, 8, 8, 8, 8, 12]
    assert [cdr_align(p, 8) for p in (4, 5, 12, 13)] == [4, 12, 12, 20]


@pytest.mark.parametrize("order", "<>")
def test_every_cut_of_a_cdr_header_is_a_cut(order: str) -> None:
    data = _cdr_header_bytes(order, 1, 2, b"lidar_top")
    for cut in range(4, len(data)):
        with pytest.raises(WireError) as exc:
            cdr_header(data[:cut], 4, order)
        assert exc.value.cut, cut
        assert "missing or cut" in str(exc.value)


def test_cut_names_the_first_missing_field() -> None:
    data = _cdr_header_bytes("<", 1, 2, b"x")
    with pytest.raises(WireError, match="a 4-byte field at byte 4 is"):
        cdr_header(data[:7], 4, "<")
    with pytest.raises(WireError, match="a 4-byte field at byte 12 is"):
        cdr_header(data[:13], 4, "<")
    with pytest.raises(WireError, match="a string of 2 bytes at byte 12 is missing or cut"):
        cdr_header(data[:17], 4, "<")


def test_a_cdr_string_needs_its_nul() -> None:
    """CDR counts the NUL in the length: an empty length or a last byte not NUL is no string."""
    for bad in (struct.pack("<I", 0), struct.pack("<I", 3) + b"abc"):
        with pytest.raises(WireError, match="has no NUL") as exc:
            cdr_string(b"\x00\x01\x00\x00" + bad, 4, "<")
        assert not exc.value.cut


def test_strings_decode_leniently() -> None:
    """Neither format requires valid UTF-8: a flipped bit is no framing error."""
    data = _cdr_header_bytes("<", 1, 2, b"fr\xffnt")
    assert cdr_header(data, 4, "<")[2] == "fr\ufffdnt"
    assert ros1_string(struct.pack("<I", 2) + b"\xc3(", 0)[0] == "\ufffd("


def test_ros1_header_string_and_time() -> None:
    data = struct.pack("<IIII", 7, 4_000_000_000, 5, 5) + b"front" + struct.pack("<I", 0)
    assert ros1_header(data, 0) == (7, 4_000_000_000, 5, "front", 21)
    assert ros1_time(data, 4) == (4_000_000_000, 5, 12)
    assert ros1_string(data, 21) == ("", 25)  # ROS 1 strings have no NUL: empty is fine
    for cut in range(len(data) - 4):
        with pytest.raises(WireError) as exc:
            ros1_header(data[:cut], 0)
        assert exc.value.cut, cut
