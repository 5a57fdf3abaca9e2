"""ROS 1 and CDR wire format: the encapsulation, times, strings and std_msgs/Header at a position.

The fast readers of serialized messages (LiDAR scans, camera records, image headers, TF) read
their headers and strings here, so the encapsulations accepted and the damage reported are
defined once.

CDR (ROS 2): a 4-byte encapsulation header, then the body, each primitive aligned to its size
counted from after that header. Accepted: CDR_BE (00 00) and CDR_LE (00 01), the plain XCDR1
the ROS 2 rmw layers write (encapsulation ids of OMG DDS-XTypes 1.3, 7.6.3.1.2). Refused:
PL_CDR_BE/LE (00 02/00 03: a parameter list, each member behind an id and a length, not the
plain layout), the XCDR2 ids (00 06 to 00 0b: other alignment), and any other. The options
(bytes 2-3) are not read. A string is a uint32 length counting its NUL, the bytes, the NUL;
builtin_interfaces/Time is int32 sec, uint32 nanosec; std_msgs/Header is stamp, frame_id.

ROS 1: little-endian and packed (no alignment, no encapsulation). A string is a uint32 length
and the bytes (no NUL); `time` is uint32 sec, uint32 nsec; std_msgs/Header is uint32 seq,
stamp, frame_id.

Damage (a field or string past the end, a CDR string without its NUL, an encapsulation not
accepted) raises `WireError`, a DecodeError with a one-line reason; `cut` tells bytes cut
short from other damage. Strings decode as UTF-8 leniently (invalid bytes become U+FFFD):
neither format requires valid text, and a name with a flipped bit is no framing error.
Values (nanoseconds past 1e9, negative seconds) are the callers' to judge.
"""

from __future__ import annotations

import struct
from typing import Final

from syncaudit.errors import DecodeError

__all__ = [
    "CDR_BYTE_ORDERS",
    "WireError",
    "cdr_align",
    "cdr_byte_order",
    "cdr_header",
    "cdr_string",
    "cdr_time",
    "ros1_header",
    "ros1_string",
    "ros1_time",
]

Buffer = bytes | bytearray | memoryview

CDR_BYTE_ORDERS: Final = {0x0000: ">", 0x0001: "<"}
"""struct byte order of each accepted CDR encapsulation id: CDR_BE and CDR_LE."""

_ENCAPSULATION: Final = struct.Struct(">H2x")  # the id (big-endian), the options
_CDR_U32: Final = {order: struct.Struct(order + "I") for order in "<>"}
_CDR_TIME: Final = {order: struct.Struct(order + "iI") for order in "<>"}  # sec, nanosec
_CDR_HEAD: Final = {order: struct.Struct(order + "iII") for order in "<>"}  # + frame_id length
_R1_U32: Final = struct.Struct("<I")
_R1_TIME: Final = struct.Struct("<II")  # sec, nsec
_R1_HEAD: Final = struct.Struct("<IIII")  # seq, sec, nsec, frame_id length


class WireError(DecodeError):
    """Serialized bytes that are no ROS 1 / CDR message: one line saying what and where."""

    def __init__(self, reason: str, *, cut: bool) -> None:
        super().__init__(reason)
        self.cut = cut
        """True where the bytes end before a field does (a message cut short)."""


def cdr_byte_order(data: Buffer) -> str:
    """ "<" or ">" from the encapsulation header of a CDR message; WireError if not accepted."""
    try:
        (encapsulation,) = _ENCAPSULATION.unpack_from(data)
        return CDR_BYTE_ORDERS[encapsulation]
    except (struct.error, KeyError):
        head = bytes(data[0:4]).hex() or "nothing"
        raise WireError(
            f"CDR encapsulation {head} of a {len(data)}-byte message is not CDR_LE or CDR_BE "
            "(0001 or 0000)",
            cut=len(data) < 4,
        ) from None


def cdr_align(pos: int, size: int) -> int:
    """`pos` moved to the next multiple of `size` counted from byte 4 (after the header)."""
    return pos + (-(pos - 4) % size)


def _cut(data: Buffer, pos: int) -> WireError:
    """The error for 4-byte fields from `pos` on that the bytes end within: names the first."""
    at = pos + 4 * max(0, (len(data) - pos) // 4)
    return WireError(f"a 4-byte field at byte {at} is missing or cut", cut=True)


def _cdr_text(data: Buffer, at: int, length: int) -> tuple[str, int]:
    """The CDR string whose length `length` was read at `at`: (text, end)."""
    end = at + 4 + length
    if end > len(data):
        raise WireError(f"a string of {length} bytes at byte {at} is missing or cut", cut=True)
    if length < 1 or data[end - 1] != 0:
        raise WireError(f"a string of {length} bytes at byte {at} has no NUL", cut=False)
    return str(data[at + 4 : end - 1], "utf-8", "replace"), end


def cdr_string(data: Buffer, pos: int, order: str) -> tuple[str, int]:
    """The CDR string whose length field is at `pos` (aligned first): (text, end)."""
    pos += -(pos - 4) % 4
    try:
        (length,) = _CDR_U32[order].unpack_from(data, pos)
    except struct.error:
        raise _cut(data, pos) from None
    return _cdr_text(data, pos, length)


def cdr_time(data: Buffer, pos: int, order: str) -> tuple[int, int, int]:
    """The builtin_interfaces/Time at `pos` (aligned first): (sec, nanosec, end)."""
    pos += -(pos - 4) % 4
    try:
        sec, nsec = _CDR_TIME[order].unpack_from(data, pos)
    except struct.error:
        raise _cut(data, pos) from None
    return sec, nsec, pos + 8


def cdr_header(data: Buffer, pos: int, order: str) -> tuple[int, int, str, int]:
    """The ROS 2 std_msgs/Header at `pos` (aligned first): (sec, nanosec, frame_id, end)."""
    pos += -(pos - 4) % 4
    try:
        sec, nsec, length = _CDR_HEAD[order].unpack_from(data, pos)
    except struct.error:
        raise _cut(data, pos) from None
    text, end = _cdr_text(data, pos + 8, length)
    return sec, nsec, text, end


def _ros1_text(data: Buffer, at: int, length: int) -> tuple[str, int]:
    """The ROS 1 string whose length `length` was read at `at`: (text, end)."""
    end = at + 4 + length
    if end > len(data):
        raise WireError(f"a string of {length} bytes at byte {at} is missing or cut", cut=True)
    return str(data[at + 4 : end], "utf-8", "replace"), end


def ros1_string(data: Buffer, pos: int) -> tuple[str, int]:
    """The ROS 1 string whose length field is at `pos`: (text, end)."""
    try:
        (length,) = _R1_U32.unpack_from(data, pos)
    except struct.error:
        raise _cut(data, pos) from None
    return _ros1_text(data, pos, length)


def ros1_time(data: Buffer, pos: int) -> tuple[int, int, int]:
    """The ROS 1 `time` at `pos`: (sec, nsec, end)."""
    try:
        sec, nsec = _R1_TIME.unpack_from(data, pos)
    except struct.error:
        raise _cut(data, pos) from None
    return sec, nsec, pos + 8


def ros1_header(data: Buffer, pos: int) -> tuple[int, int, int, str, int]:
    """The ROS 1 std_msgs/Header at `pos`: (seq, sec, nsec, frame_id, end)."""
    try:
        seq, sec, nsec, length = _R1_HEAD.unpack_from(data, pos)
    except struct.error:
        raise _cut(data, pos) from None
    text, end = _ros1_text(data, pos + 12, length)
    return seq, sec, nsec, text, end
