"""Records of a pcap or pcapng capture, streamed from a byte range of the file.

Classic pcap (libpcap): a 24-byte file header (magic A1B2C3D4 for microsecond, A1B23C4D for
nanosecond time stamps, in either byte order), then records of a 16-byte header (seconds,
sub-second, captured length, original length) and the captured bytes.

pcapng: blocks of (type, total length, body, total length), 4-byte aligned; the section
header block (0x0A0D0D0A) gives the byte order by its magic 1A2B3C4D, interface description
blocks (1) the link type and time-stamp resolution (option 9, `if_tsresol`) of each
interface, enhanced (6) and simple (3) packet blocks the packets. Other blocks are skipped.

Written here rather than taken from a library: dpkt and python-pcapng parse each record into
objects (2-10x slower, figures in docs/reading.md), neither says where a truncated file was
cut, and neither can start at a byte offset, which chunk-parallel reading needs: a reader of
a byte range starts at the first record header at or after its offset that chains with the
next records (`sync_offset`), and reads the records that start before its end.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import BinaryIO

from syncaudit.errors import LogOpenError, LogReadError

PCAP_MAGICS: dict[bytes, tuple[str, int]] = {
    b"\xd4\xc3\xb2\xa1": ("<", 1_000),
    b"\xa1\xb2\xc3\xd4": (">", 1_000),
    b"\x4d\x3c\xb2\xa1": ("<", 1),
    b"\xa1\xb2\x3c\x4d": (">", 1),
}
"""Classic pcap magic -> (byte order, nanoseconds per sub-second unit)."""
PCAPNG_MAGIC = b"\x0a\x0d\x0d\x0a"
"""pcapng: the section header block type (its byte-order magic follows the length)."""

FILE_HEADER_BYTES = 24
RECORD_HEADER_BYTES = 16
MAX_SNAPLEN = 262_144
"""libpcap's largest snap length: a captured record longer than this is damage."""
MAX_RECORDS = 2**32 - 1
"""More records than a 32-bit counter holds: refused (a hostile or looping file)."""
MAX_BLOCK_BYTES = 16 * 1024 * 1024
"""A pcapng block longer than this is damage (snap lengths stop at 256 KiB)."""
SYNC_CHAIN = 16
"""Record headers that must chain for a byte offset to count as a record boundary."""
SYNC_CHAIN_MIN = 4
"""Chained headers enough where the read window ends first (records of up to 256 KiB)."""
SYNC_SPAN_S = 7 * 86_400
"""A classic record boundary's time stamp lies within this of the capture's first one."""
READ_BYTES = 4 * 1024 * 1024
"""Bytes read from the file at a time."""

BLOCK_SHB = 0x0A0D0D0A
BLOCK_IDB = 1
BLOCK_SPB = 3
BLOCK_EPB = 6
_NG_KNOWN_BLOCKS = frozenset({BLOCK_SHB, BLOCK_IDB, 2, BLOCK_SPB, 4, 5, BLOCK_EPB, 7, 9, 10})


@dataclass(frozen=True, slots=True)
class Record:
    """One captured packet: where its record starts, when it was captured, its bytes."""

    offset: int
    time_ns: int
    """Capture time stamp (the capturing host's clock), ns since the epoch."""
    link_type: int
    data: bytes
    orig_len: int


@dataclass(frozen=True, slots=True)
class Interface:
    """A pcapng interface (or the classic file's one): link type, ns per time unit, snap."""

    link_type: int
    unit_ns: float
    snaplen: int


@dataclass(slots=True)
class CaptureFormat:
    """What the start of a capture says: format, byte order, interfaces, first record."""

    kind: str
    """'pcap' or 'pcapng'."""
    endian: str
    interfaces: list[Interface] = field(default_factory=list)
    first_record: int = FILE_HEADER_BYTES
    first_second: int | None = None
    """Classic pcap: the first record's seconds (what `sync_offset` checks stamps against)."""


def read_format(handle: BinaryIO, path: str, size: int) -> CaptureFormat:
    """The capture's format from its first bytes; LogOpenError (one line) if hostile."""
    handle.seek(0)
    head = handle.read(FILE_HEADER_BYTES)
    if head[:4] in PCAP_MAGICS:
        if len(head) < FILE_HEADER_BYTES:
            raise LogOpenError(f"{path}: pcap file header cut at {len(head)} of 24 bytes")
        endian, unit_ns = PCAP_MAGICS[head[:4]]
        major, _minor, _zone, _sigfigs, snaplen, link = struct.unpack(endian + "HHiIII", head[4:])
        if major != 2:
            raise LogOpenError(f"{path}: pcap version {major} is not 2")
        if snaplen == 0:
            raise LogOpenError(f"{path}: pcap snap length is 0 (no packet could be captured)")
        snap = min(snaplen, MAX_SNAPLEN) if snaplen < 2**31 else MAX_SNAPLEN
        first = handle.read(4)
        second = struct.unpack(endian + "I", first)[0] if len(first) == 4 else None
        iface = Interface(link & 0x0FFFFFFF, unit_ns, snap)
        return CaptureFormat("pcap", endian, [iface], first_second=second)
    if head[:4] == PCAPNG_MAGIC:
        return _read_ng_head(handle, path, size)
    raise LogOpenError(f"{path}: not a pcap or pcapng capture")


def _read_ng_head(handle: BinaryIO, path: str, size: int) -> CaptureFormat:
    """pcapng: byte order from the section header, interfaces from the blocks up to the
    first packet block (where interfaces are described, in every capture tool's files)."""
    handle.seek(0)
    head = handle.read(12)
    if len(head) < 12:
        raise LogOpenError(f"{path}: pcapng section header cut at {len(head)} bytes")
    bom = head[8:12]
    if bom == b"\x4d\x3c\x2b\x1a":
        endian = "<"
    elif bom == b"\x1a\x2b\x3c\x4d":
        endian = ">"
    else:
        raise LogOpenError(f"{path}: pcapng byte-order magic {bom.hex()} is not 1A2B3C4D")
    fmt = CaptureFormat("pcapng", endian)
    offset = 0
    while offset < size:
        block = _ng_block(handle, path, size, offset, endian)
        if block is None:
            break
        btype, body = block
        if btype == BLOCK_IDB:
            fmt.interfaces.append(_interface(body, endian, path))
        elif btype in (BLOCK_EPB, BLOCK_SPB):
            break
        offset += 12 + len(body)
    fmt.first_record = offset
    return fmt


def _ng_block(
    handle: BinaryIO, path: str, size: int, offset: int, endian: str
) -> tuple[int, bytes] | None:
    """(type, body) of the pcapng block at `offset`; None at a cut end."""
    handle.seek(offset)
    head = handle.read(8)
    if len(head) < 8:
        return None
    btype, total = struct.unpack(endian + "II", head)
    _check_ng_length(path, offset, total, size)
    rest = handle.read(total - 8)
    if len(rest) < total - 8:
        return None
    return btype, rest[:-4]


def _check_ng_length(path: str, offset: int, total: int, size: int) -> None:
    if total < 12 or total % 4 or total > MAX_BLOCK_BYTES:
        raise LogReadError(f"{path}: pcapng block at byte {offset} has a bad length {total}")


def _interface(body: bytes, endian: str, path: str) -> Interface:
    """An interface description block's link type, time unit (if_tsresol) and snap length."""
    if len(body) < 8:
        raise LogReadError(f"{path}: pcapng interface block of {len(body)} bytes")
    link, _reserved, snaplen = struct.unpack(endian + "HHI", body[:8])
    unit_ns = 1_000.0
    pos = 8
    while pos + 4 <= len(body):
        code, length = struct.unpack(endian + "HH", body[pos : pos + 4])
        if code == 0:
            break
        if code == 9 and length >= 1:
            res = body[pos + 4]
            unit_s = 2.0 ** -(res & 0x7F) if res & 0x80 else 10.0 ** -(res & 0x7F)
            unit_ns = unit_s * 1e9
        pos += 4 + ((length + 3) & ~3)
    return Interface(link, unit_ns, snaplen or MAX_SNAPLEN)


@dataclass(slots=True)
class RecordStream:
    """Records of a byte range [start, stop) of one capture: those whose header starts in
    it. `cut_at` is set where the file ends inside a record (a truncated capture)."""

    handle: BinaryIO
    path: str
    size: int
    fmt: CaptureFormat
    cut_at: int | None = None
    records: int = 0

    def iter_range(self, start: int, stop: int) -> Iterator[Record]:
        """Every record starting in [start, stop) (start must be a record boundary)."""
        if self.fmt.kind == "pcap":
            yield from self._pcap(start, stop)
        else:
            yield from self._pcapng(start, stop)

    def _count(self, offset: int) -> None:
        self.records += 1
        if self.records > MAX_RECORDS:
            raise LogReadError(f"{self.path}: more than 2^32 - 1 records at byte {offset}")

    def _pcap(self, start: int, stop: int) -> Iterator[Record]:
        endian = self.fmt.endian
        iface = self.fmt.interfaces[0]
        unit_ns = int(iface.unit_ns)
        header = struct.Struct(endian + "IIII")
        buf = b""
        base = start
        pos = 0
        self.handle.seek(start)
        while base + pos < stop:
            if len(buf) - pos < RECORD_HEADER_BYTES:
                buf, base, pos = self._refill(buf, base, pos)
                if len(buf) - pos < RECORD_HEADER_BYTES:
                    if len(buf) > pos:
                        self.cut_at = base + pos
                    return
            sec, sub, incl, orig = header.unpack_from(buf, pos)
            offset = base + pos
            if incl > iface.snaplen or incl > MAX_SNAPLEN:
                raise LogReadError(
                    f"{self.path}: record at byte {offset} claims {incl} captured bytes, past "
                    f"the snap length {iface.snaplen}"
                )
            if offset + RECORD_HEADER_BYTES + incl > self.size:
                self.cut_at = offset
                return
            end = pos + RECORD_HEADER_BYTES + incl
            if end > len(buf):
                buf, base, pos = self._refill(buf, base, pos)
                end = pos + RECORD_HEADER_BYTES + incl
            self._count(offset)
            data = buf[pos + RECORD_HEADER_BYTES : end]
            yield Record(offset, sec * 1_000_000_000 + sub * unit_ns, iface.link_type, data, orig)
            pos = end

    def _refill(self, buf: bytes, base: int, pos: int) -> tuple[bytes, int, int]:
        """Keep the unread tail and read the next READ_BYTES after it."""
        tail = buf[pos:]
        more = self.handle.read(READ_BYTES)
        return tail + more, base + pos, 0

    def _pcapng(self, start: int, stop: int) -> Iterator[Record]:
        endian = self.fmt.endian
        head = struct.Struct(endian + "II")
        offset = start
        while offset < stop:
            self.handle.seek(offset)
            raw = self.handle.read(8)
            if len(raw) < 8:
                if raw:
                    self.cut_at = offset
                return
            btype, total = head.unpack(raw)
            _check_ng_length(self.path, offset, total, self.size)
            if offset + total > self.size:
                self.cut_at = offset
                return
            body = self.handle.read(total - 8)[:-4]
            if btype == BLOCK_EPB:
                record = self._epb(body, offset)
                if record is not None:
                    yield record
            elif btype == BLOCK_SPB:
                iface = self._iface(0, offset)
                (orig,) = struct.unpack(endian + "I", body[:4])
                self._count(offset)
                yield Record(
                    offset, 0, iface.link_type, body[4 : 4 + min(orig, iface.snaplen)], orig
                )
            elif btype == BLOCK_IDB and offset >= self.fmt.first_record:
                self.fmt.interfaces.append(_interface(body, endian, self.path))
            elif btype == BLOCK_SHB and offset > 0:
                raise LogReadError(
                    f"{self.path}: a second pcapng section at byte {offset} (concatenated "
                    "captures are not read; split them)"
                )
            offset += total

    def _iface(self, index: int, offset: int) -> Interface:
        if index >= len(self.fmt.interfaces):
            raise LogReadError(
                f"{self.path}: packet block at byte {offset} names interface {index}, "
                f"of {len(self.fmt.interfaces)} described"
            )
        return self.fmt.interfaces[index]

    def _epb(self, body: bytes, offset: int) -> Record | None:
        if len(body) < 20:
            raise LogReadError(f"{self.path}: enhanced packet block at byte {offset} too short")
        index, high, low, incl, orig = struct.unpack(self.fmt.endian + "IIIII", body[:20])
        iface = self._iface(index, offset)
        if incl > len(body) - 20:
            raise LogReadError(
                f"{self.path}: packet block at byte {offset} claims {incl} captured bytes, "
                f"past its block"
            )
        self._count(offset)
        ticks = (high << 32) | low
        unit = iface.unit_ns
        time_ns = ticks * int(unit) if unit >= 1 and unit == int(unit) else int(ticks * unit)
        return Record(offset, time_ns, iface.link_type, body[20 : 20 + incl], orig)


def sync_offset(handle: BinaryIO, fmt: CaptureFormat, size: int, offset: int) -> int:
    """The first record boundary at or after `offset` (`size` if none): a position whose
    record header, and the SYNC_CHAIN - 1 after it, are plausible and chain."""
    if offset <= fmt.first_record:
        return fmt.first_record
    window = 2 * MAX_SNAPLEN + 64 * 1024
    handle.seek(offset)
    buf = handle.read(window)
    step = 4 if fmt.kind == "pcapng" else 1
    start = (-offset) % step
    for pos in range(start, len(buf), step):
        if _chains(buf, pos, fmt, offset + pos, size):
            return offset + pos
    return size


def _chains(buf: bytes, pos: int, fmt: CaptureFormat, at: int, size: int) -> bool:
    """Whether SYNC_CHAIN plausible record headers chain from `buf[pos]` (SYNC_CHAIN_MIN
    where the window ends first; the last one may end the file exactly)."""
    endian = fmt.endian
    for checked in range(SYNC_CHAIN):
        if at == size:
            return True
        if pos + 16 > len(buf):
            return checked >= SYNC_CHAIN_MIN
        if fmt.kind == "pcap":
            sec, sub, incl, orig = struct.unpack_from(endian + "IIII", buf, pos)
            unit_ns = fmt.interfaces[0].unit_ns
            if sub * unit_ns >= 1e9 or incl > fmt.interfaces[0].snaplen or orig < incl:
                return False
            if incl == 0 or orig > MAX_SNAPLEN * 256:
                return False
            if fmt.first_second is not None and abs(sec - fmt.first_second) > SYNC_SPAN_S:
                return False
            step = RECORD_HEADER_BYTES + incl
        else:
            btype, total = struct.unpack_from(endian + "II", buf, pos)
            if btype not in _NG_KNOWN_BLOCKS or total < 12 or total % 4 or total > MAX_BLOCK_BYTES:
                return False
            if pos + total <= len(buf):
                (trail,) = struct.unpack_from(endian + "I", buf, pos + total - 4)
                if trail != total:
                    return False
            step = total
        pos += step
        at += step
        if at > size:
            return False
    return True
