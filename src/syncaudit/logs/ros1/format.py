"""ROS 1 bag format 2.0: records, the index, a chunk scan for bags without one, chunk reading.

Format (wiki.ros.org/Bags/Format/2.0): after the line `#ROSBAG V2.0\\n` come records, each
`<header_len u32><header><data_len u32><data>`; a header is a run of
`<field_len u32><name>=<value>` fields, `op` (u8) naming the record:

- 0x03 bag header: `index_pos` (u64), `conn_count`, `chunk_count` (u32); padded to 4 KiB.
- 0x05 chunk: `compression` ('none', 'bz2', 'lz4'), `size` (uncompressed, u32); its data
  holds message data (0x02: `conn`, `time`) and connection (0x07) records.
- 0x04 index data after each chunk: per connection, (time, offset in chunk) entries.
- 0x07 connection (`conn`, `topic`; data: a header with `type`, `md5sum`,
  `message_definition`, optional `callerid`, `latching`), then 0x06 chunk info
  (`chunk_pos`, `start_time`, `end_time`, `count`; data: (conn, count) pairs) — the index
  section at `index_pos`, written when the recording closes.

`lz4` chunks are LZ4 *frames* (roslz4 writes the frame format; rosbags and Embag read them
with the LZ4F frame decoder); `lz4_frame` walks them block by block, leaving blocks
stored uncompressed in the file (see `Rosbag1ChunkReader`). A bag whose recorder died has
`index_pos` 0 or an index cut off: it is then read by scanning the chunks from the start,
as `rosbag reindex` does.
"""

from __future__ import annotations

import bisect
import bz2
import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

import lz4.frame

from syncaudit.errors import LogReadError
from syncaudit.logs.magic import ROSBAG1_MAGIC
from syncaudit.logs.model import ChannelInfo, ReadUnit
from syncaudit.logs.ros1.lz4_frame import (
    FileSpan,
    FrameError,
    FrameSource,
    Pieces,
    decode_frame,
)
from syncaudit.logs.typesys import normalise_type_name, one_line

MAGIC = ROSBAG1_MAGIC
OP_MSG_DATA = 0x02
OP_BAG_HEADER = 0x03
OP_INDEX_DATA = 0x04
OP_CHUNK = 0x05
OP_CHUNK_INFO = 0x06
OP_CONNECTION = 0x07
UNIT_KIND = "rosbag1-chunk"
COMPRESSIONS = ("none", "bz2", "lz4")
MAX_CHUNK_BYTES = 1 << 30
"""Largest uncompressed chunk accepted (rosbag's default chunk is 768 KiB; a chunk grows past
that only by one message bigger than it). Bounds what a hostile `size` field can allocate."""
MAX_RATIO = 1000
"""Largest uncompressed/compressed ratio accepted for chunks over 16 MiB (decompression bombs)."""

MAX_HEADER_BYTES = 1 << 20
"""Largest record header accepted: headers hold a few short fields (a topic, a type name);
a larger length is damage, not a record cut off by the end of the file."""

_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")
_TIME = struct.Struct("<II")


class BagFormatError(Exception):
    """A record that does not follow the format, at a byte offset of the file."""

    def __init__(self, offset: int, problem: str) -> None:
        super().__init__(f"{problem} at byte {offset}")
        self.offset = offset
        self.problem = problem


class BagEncryptedError(BagFormatError):
    """A bag written with rosbag's encryption plugin (its chunks cannot be read)."""


class BagCutError(BagFormatError):
    """A record whose bytes run past the end of the file (or of its chunk)."""


def parse_header(buf: bytes | memoryview, start: int, end: int) -> dict[str, bytes]:
    """The fields of a record header `buf[start:end]` by name (raises ValueError)."""
    fields: dict[str, bytes] = {}
    pos = start
    while pos < end:
        if pos + 4 > end:
            raise ValueError("header field length cut off")
        (size,) = _U32.unpack_from(buf, pos)
        pos += 4
        if pos + size > end:
            raise ValueError("header field overruns its header")
        raw = bytes(buf[pos : pos + size])
        name, sep, value = raw.partition(b"=")
        if not sep:
            raise ValueError("header field without '='")
        fields[name.decode("ascii", "replace")] = value
        pos += size
    return fields


def _op(fields: dict[str, bytes]) -> int:
    value = fields.get("op")
    if value is None or len(value) != 1:
        raise ValueError("record header has no one-byte 'op'")
    return value[0]


def _u32(fields: dict[str, bytes], name: str) -> int:
    value = fields.get(name)
    if value is None or len(value) != 4:
        raise ValueError(f"record header field {name!r} is not a uint32")
    return int(_U32.unpack(value)[0])


def _u64(fields: dict[str, bytes], name: str) -> int:
    value = fields.get(name)
    if value is None or len(value) != 8:
        raise ValueError(f"record header field {name!r} is not a uint64")
    return int(_U64.unpack(value)[0])


def _time(fields: dict[str, bytes], name: str) -> int:
    value = fields.get(name)
    if value is None or len(value) != 8:
        raise ValueError(f"record header field {name!r} is not a time")
    sec, nsec = _TIME.unpack(value)
    return int(sec) * 1_000_000_000 + int(nsec)


def _text(fields: dict[str, bytes], name: str) -> str:
    value = fields.get(name)
    if value is None:
        raise ValueError(f"record header has no {name!r}")
    return value.decode("utf-8", "replace")


def normalise_topic(name: str) -> str:
    """Collapse repeated slashes as rosbags does ('//a//b/' -> '/a/b'), for identical topics."""
    return ("/" if name.startswith("/") else "") + "/".join(x for x in name.split("/") if x)


@dataclass(frozen=True, slots=True)
class Connection:
    """One connection record: a topic as published by one node, with its type definition."""

    conn_id: int
    topic: str
    msgtype: str
    """ROS 2 style name ('sensor_msgs/msg/Image'), as rosbags and schemas/ spell it."""
    md5sum: str
    definition: str
    callerid: str | None
    latching: bool


def parse_connection(fields: dict[str, bytes], data: bytes | memoryview) -> Connection:
    """A Connection from a connection record's header fields and data (raises ValueError)."""
    conn_id = _u32(fields, "conn")
    topic = normalise_topic(_text(fields, "topic"))
    inner = parse_header(data, 0, len(data))
    latching = inner.get("latching", b"0").strip() not in (b"", b"0")
    return Connection(
        conn_id=conn_id,
        topic=topic,
        msgtype=normalise_type_name(_text(inner, "type")),
        md5sum=inner.get("md5sum", b"").decode("ascii", "replace"),
        definition=inner.get("message_definition", b"").decode("utf-8", "replace"),
        callerid=inner["callerid"].decode("utf-8", "replace") if "callerid" in inner else None,
        latching=latching,
    )


@dataclass(slots=True)
class ChunkSpan:
    """What the index (or the scan) knows of one chunk record."""

    offset: int
    length: int
    """Bytes of the chunk record (to the cut for the chunk a recording was cut inside)."""
    compressed_bytes: int
    start_ns: int
    end_ns: int
    counts: dict[int, int] = field(default_factory=dict)
    """Messages per connection id."""


@dataclass(slots=True)
class BagIndex:
    """Connections and chunks of a bag, from its index or from scanning its chunks."""

    connections: dict[int, Connection]
    chunks: list[ChunkSpan]
    cut_at: int | None = None
    """Byte offset where the file ends inside a record (None: the file is whole)."""
    damage: str | None = None
    """Why the index was not used (None: it was)."""


class BagFile:
    """A file read at offsets, with its size."""

    def __init__(self, handle: BinaryIO, size: int) -> None:
        self.handle = handle
        self.size = size

    def read(self, offset: int, length: int) -> bytes:
        """Up to `length` bytes at `offset` (fewer at the end; none past it, whatever the
        offset a damaged field names)."""
        length = min(length, self.size - offset)
        if offset < 0 or length <= 0:
            return b""
        self.handle.seek(offset)
        return self.handle.read(length)

    def record_at(self, offset: int) -> tuple[dict[str, bytes], int, int]:
        """(header fields, data offset, data length) of the record at `offset`.

        Raises BagCutError where the file ends inside the record, BagFormatError where the
        header is unreadable.
        """
        head = self.read(offset, 4)
        if len(head) < 4:
            raise BagCutError(offset, "record header length cut off")
        (hlen,) = _U32.unpack(head)
        if hlen > MAX_HEADER_BYTES:
            raise BagFormatError(offset, f"record header length {hlen} is not plausible")
        raw = self.read(offset + 4, hlen + 4)
        if len(raw) < hlen + 4:
            raise BagCutError(offset, "record header cut off")
        try:
            fields = parse_header(raw, 0, hlen)
        except ValueError as exc:
            raise BagFormatError(offset, f"unreadable record header ({exc})") from None
        (dlen,) = _U32.unpack_from(raw, hlen)
        data_at = offset + 8 + hlen
        return fields, data_at, dlen


def read_bag_header(bag: BagFile) -> tuple[int, int, int, int]:
    """(index_pos, conn_count, chunk_count, offset of the first record after it)."""
    fields, data_at, dlen = bag.record_at(len(MAGIC))
    try:
        if _op(fields) != OP_BAG_HEADER:
            raise ValueError("first record is not the bag header")
        index_pos = _u64(fields, "index_pos")
        conn_count = _u32(fields, "conn_count")
        chunk_count = _u32(fields, "chunk_count")
    except ValueError as exc:
        raise BagFormatError(len(MAGIC), str(exc)) from None
    encryptor = fields.get("encryptor", b"").decode("utf-8", "replace")
    if encryptor:
        raise BagEncryptedError(len(MAGIC), encryptor)
    return index_pos, conn_count, chunk_count, data_at + dlen


def read_index(bag: BagFile, index_pos: int, conn_count: int, chunk_count: int) -> BagIndex:
    """The index section: connections, chunk infos, each chunk's record length.

    Raises BagFormatError (or BagCutError) where any of it is unreadable: the caller scans.
    """
    connections: dict[int, Connection] = {}
    chunks: list[ChunkSpan] = []
    pos = index_pos
    for number in range(conn_count + chunk_count):
        fields, data_at, dlen = bag.record_at(pos)
        if data_at + dlen > bag.size:
            raise BagCutError(pos, "index record cut off")
        data = bag.read(data_at, dlen)
        try:
            op = _op(fields)
            if number < conn_count:
                if op != OP_CONNECTION:
                    raise ValueError(f"expected a connection record, found op {op:#04x}")
                conn = parse_connection(fields, data)
                connections[conn.conn_id] = conn
            else:
                if op != OP_CHUNK_INFO:
                    raise ValueError(f"expected a chunk info record, found op {op:#04x}")
                if _u32(fields, "ver") != 1:
                    raise ValueError("chunk info version is not 1")
                count = _u32(fields, "count")
                if len(data) != 8 * count:
                    raise ValueError("chunk info data does not hold its count")
                pairs = struct.unpack(f"<{2 * count}I", data)
                span = ChunkSpan(
                    offset=_u64(fields, "chunk_pos"),
                    length=0,
                    compressed_bytes=0,
                    start_ns=_time(fields, "start_time"),
                    end_ns=_time(fields, "end_time"),
                    counts=dict(zip(pairs[::2], pairs[1::2], strict=True)),
                )
                chunks.append(span)
        except ValueError as exc:
            raise BagFormatError(pos, f"bad index record ({exc})") from None
        pos = data_at + dlen
    for span in chunks:
        fields, data_at, dlen = bag.record_at(span.offset)
        try:
            if _op(fields) != OP_CHUNK:
                raise ValueError("chunk info points at a record that is not a chunk")
        except ValueError as exc:
            raise BagFormatError(span.offset, str(exc)) from None
        if data_at + dlen > index_pos:
            raise BagFormatError(span.offset, "chunk overruns the index section")
        span.length = data_at + dlen - span.offset
        span.compressed_bytes = dlen
        unknown = set(span.counts) - set(connections)
        if unknown:
            raise BagFormatError(span.offset, f"chunk holds unknown connection {min(unknown)}")
    return BagIndex(connections, chunks)


def scan_chunks(bag: BagFile, first: int) -> BagIndex:
    """Walk the records from `first`, decompressing each chunk, as `rosbag reindex` does.

    Stops at the end of the file or at the first record that is cut off or unreadable; a
    chunk cut off keeps the complete messages before the cut (streamed decompression).
    """
    index = BagIndex({}, [])
    pos = first
    while pos < bag.size:
        try:
            fields, data_at, dlen = bag.record_at(pos)
            op = _op_at(fields, pos)
        except BagCutError:
            index.cut_at = bag.size
            break
        except BagFormatError as exc:
            index.damage = one_line(exc)
            break
        end = data_at + dlen
        cut = end > bag.size
        if op == OP_CHUNK:
            length = min(end, bag.size) - pos
            span = ChunkSpan(pos, length, min(dlen, bag.size - data_at), 0, 0)
            if not _scan_chunk(bag, span, index.connections, partial=cut):
                if cut:
                    index.cut_at = bag.size
                    break
                index.damage = f"chunk at byte {pos} unreadable"
                break
            if span.counts:
                index.chunks.append(span)
        elif op == OP_CONNECTION and not cut:
            try:
                conn = parse_connection(fields, bag.read(data_at, dlen))
            except ValueError:
                pass  # the copy inside a chunk already named it, or nothing needs it
            else:
                index.connections.setdefault(conn.conn_id, conn)
        if cut:
            index.cut_at = bag.size
            break
        pos = end
    return index


def _op_at(fields: dict[str, bytes], offset: int) -> int:
    try:
        return _op(fields)
    except ValueError as exc:
        raise BagFormatError(offset, str(exc)) from None


def _scan_chunk(
    bag: BagFile, span: ChunkSpan, connections: dict[int, Connection], *, partial: bool
) -> bool:
    """Fill `span` (counts, times) and `connections` from the chunk's records.

    `partial`: the chunk is cut off by the end of the file. False where the chunk is
    damaged (a whole one) or not one record of it could be read (a cut one).
    """
    try:
        body = chunk_body(bag.read(span.offset, span.length), span.offset, partial=partial)
        records = list(walk_records(body, span.offset, partial=partial))
    except LogReadError:
        return False
    start: int | None = None
    end: int | None = None
    found = False
    for op, fields, data in records:
        found = True
        try:
            if op == OP_CONNECTION:
                conn = parse_connection(fields, data)
                connections.setdefault(conn.conn_id, conn)
            elif op == OP_MSG_DATA:
                conn_id = _u32(fields, "conn")
                t = _time(fields, "time")
                span.counts[conn_id] = span.counts.get(conn_id, 0) + 1
                start = t if start is None else min(start, t)
                end = t if end is None else max(end, t)
        except ValueError:
            break
    span.start_ns = start or 0
    span.end_ns = end or 0
    return found


def chunk_head(
    record: bytes | memoryview, offset: int, *, partial: bool = False
) -> tuple[str, int, memoryview]:
    """(compression, uncompressed size, data) of the chunk record `record` (at `offset`).

    The size is refused where it cannot be honest (over `MAX_CHUNK_BYTES`, or a large one
    over `MAX_RATIO` times the data). `partial`: the record is cut off, its data may be
    short. Raises LogReadError.
    """
    where = f"ROS 1 chunk at byte {offset}"
    if len(record) < 8:
        raise LogReadError(f"{where}: record cut off")
    (hlen,) = _U32.unpack_from(record, 0)
    if 8 + hlen > len(record):
        raise LogReadError(f"{where}: record header cut off")
    try:
        fields = parse_header(record, 4, 4 + hlen)
        compression = _text(fields, "compression")
        size = _u32(fields, "size")
    except ValueError as exc:
        raise LogReadError(f"{where}: unreadable chunk header ({exc})") from None
    (dlen,) = _U32.unpack_from(record, 4 + hlen)
    data = memoryview(record)[8 + hlen : 8 + hlen + dlen]
    if len(data) < dlen and not partial:
        raise LogReadError(f"{where}: chunk data cut off ({len(data)} of {dlen} bytes)")
    if size > MAX_CHUNK_BYTES or (size > 1 << 24 and size > MAX_RATIO * max(dlen, 1)):
        raise LogReadError(
            f"{where}: chunk claims {size} uncompressed bytes from {dlen} (refused as a "
            "decompression bomb or a damaged size field)"
        )
    return compression, size, data


def chunk_body(
    record: bytes | memoryview, offset: int, *, partial: bool = False
) -> bytes | memoryview:
    """The uncompressed records of the chunk record `record` (at `offset` in its file).

    `partial`: the record is cut off; return what decompresses of it. Raises LogReadError.
    """
    where = f"ROS 1 chunk at byte {offset}"
    compression, size, data = chunk_head(record, offset, partial=partial)
    try:
        body: bytes | memoryview
        if compression == "none":
            body = data  # a view of the record: no copy
        elif compression == "bz2":
            body = bz2.BZ2Decompressor().decompress(data, max_length=size + 1)
        elif compression == "lz4":
            # The low-level call takes the view as it is (LZ4FrameDecompressor copies a
            # memoryview to bytes first: a whole chunk per chunk).
            context = lz4.frame.create_decompression_context()
            body, _read, _end = lz4.frame.decompress_chunk(context, data, max_length=size + 1)
        else:
            raise LogReadError(
                f"{where}: chunk compression {compression!r} is not one of {COMPRESSIONS}"
            )
    except LogReadError:
        raise
    except Exception as exc:  # bz2 OSError, lz4 RuntimeError on damaged streams
        raise LogReadError(f"{where}: {compression} data damaged: {one_line(exc)}") from None
    if len(body) != size and not partial:
        raise LogReadError(
            f"{where}: chunk decompresses to {len(body)} bytes, its header says {size}"
        )
    return body


def open_bag_file(path: Path) -> BagFile:
    """Open a bag file for reading at offsets (caller closes `.handle`)."""
    handle = path.open("rb")
    handle.seek(0, 2)
    size = handle.tell()
    return BagFile(handle, size)


_MSG_HEAD_BYTES = 38
"""Header bytes of a message data record holding just `op`, `conn` and `time`."""
_MSG_OP_FIRST = struct.Struct("<I3sBI5sII5sII")
"""That header as rosbags and rosbag's Python writer write it: op, conn, time."""
_MSG_CONN_FIRST = struct.Struct("<I5sII3sBI5sII")
"""That header with its fields sorted by name (rosbag's C++ writer keeps them in a
std::map): conn, op, time. Any other layout is parsed field by field."""


def whole(body: bytes | memoryview) -> Pieces:
    """Pieces of a body held in one buffer."""
    return Pieces([0], [body], len(body))


READ_AHEAD_BYTES = 1024
"""Bytes read at once from a stored block left in the file: a record header and an image's
header prefix, or a few small records, in one `pread`."""


class _PieceCursor:
    """Reads content of `Pieces` at offsets; joins pieces only for a read that spans them.

    A piece left in the file (`FileSpan`) is read `READ_AHEAD_BYTES` at a time (or what a
    read asks, if more), never whole.
    """

    __slots__ = ("base", "buf", "pieces", "top")

    def __init__(self, pieces: Pieces) -> None:
        self.pieces = pieces
        self.buf: bytes | memoryview = b""
        self.base = self.top = 0

    def at(self, pos: int, size: int) -> tuple[bytes | memoryview, int]:
        """(buffer, offset in it) of content bytes `pos` to `pos + size` (within the
        content: the caller checks)."""
        if self.base <= pos and pos + size <= self.top:
            return self.buf, pos - self.base
        starts, buffers = self.pieces.starts, self.pieces.buffers
        k = bisect.bisect_right(starts, pos) - 1
        piece, start = buffers[k], starts[k]
        end = start + len(piece)
        if pos + size <= end:
            if isinstance(piece, FileSpan):
                stop = min(end, pos + max(size, READ_AHEAD_BYTES))
                self.buf, self.base, self.top = piece.read(pos - start, stop - start), pos, stop
            else:
                self.buf, self.base, self.top = piece, start, end
            return self.buf, pos - self.base
        # Spanning pieces (a LiDAR scan over many blocks): gathered into one new buffer,
        # each piece copied once (read straight into it from the file).
        out = bytearray(size)
        view = memoryview(out)
        got, first = 0, pos - start
        for piece in buffers[k:]:
            n = min(len(piece) - first, size - got)
            if isinstance(piece, FileSpan):
                piece.read_into(view[got : got + n], first)
            else:
                view[got : got + n] = piece[first : first + n]
            got += n
            first = 0
            if got >= size:
                break
        return view, 0


def _records(
    cursor: _PieceCursor, offset: int, *, partial: bool
) -> Iterator[tuple[int, bytes | memoryview, int, int, int, int]]:
    """(record offset, buffer, header offset in it, header length, data offset, data length)
    of each record of an uncompressed chunk body, its framing checked; the buffer holds the
    header and the data length after it.

    `partial`: the body is the start of a cut-off chunk; stop quietly at the first
    incomplete record. Otherwise a record overrunning the body raises LogReadError naming
    the chunk's `offset` and the offset in the chunk.
    """
    size = cursor.pieces.size
    pos = 0
    while pos < size:
        problem = ""
        if pos + 4 > size:
            problem = "record cut off"
        else:
            buf, at = cursor.at(pos, 4)
            (hlen,) = _U32.unpack_from(buf, at)
            data_at = pos + 8 + hlen
            if data_at > size:
                problem = "record header overruns the chunk"
            else:
                buf, at = cursor.at(pos + 4, hlen + 4)
                (dlen,) = _U32.unpack_from(buf, at + hlen)
                if data_at + dlen > size:
                    problem = "record data overruns the chunk"
        if problem:
            if partial:
                return
            raise LogReadError(
                f"ROS 1 chunk at byte {offset}: {problem} (offset {pos} in the chunk)"
            )
        yield pos, buf, at, hlen, data_at, dlen
        pos = data_at + dlen


def _header(
    buf: bytes | memoryview, at: int, hlen: int, offset: int, pos: int
) -> tuple[dict[str, bytes], int]:
    """(fields, op) of the record header at `buf[at:at + hlen]`; LogReadError if unreadable."""
    try:
        fields = parse_header(buf, at, at + hlen)
        return fields, _op(fields)
    except ValueError as exc:
        raise LogReadError(
            f"ROS 1 chunk at byte {offset}: unreadable record (offset {pos} in the chunk: {exc})"
        ) from None


def walk_records(
    body: bytes | memoryview, offset: int, *, partial: bool = False
) -> Iterator[tuple[int, dict[str, bytes], memoryview]]:
    """(op, header fields, data) of each record in an uncompressed chunk body.

    `partial`: the body is the decompressed start of a cut-off chunk; stop quietly at the
    first incomplete record. Otherwise a record overrunning the body raises LogReadError.
    """
    cursor = _PieceCursor(whole(body))
    for pos, buf, at, hlen, data_at, dlen in _records(cursor, offset, partial=partial):
        try:
            fields, op = _header(buf, at, hlen, offset, pos)
        except LogReadError:
            if partial:
                return
            raise
        data, data_pos = cursor.at(data_at, dlen)
        yield op, fields, memoryview(data)[data_pos : data_pos + dlen]


def wanted_messages(
    pieces: Pieces, channels: dict[int, ChannelInfo], offset: int, *, partial: bool = False
) -> Iterator[tuple[int, int, int, bytes | memoryview]]:
    """(log time, message index, connection id, payload) of the messages of `channels` in
    an uncompressed chunk body, in file order (the index counts every message record).

    A channel with `prefix_bytes` gets that much of its payloads (an image's header), so
    pixels stored in blocks of their own are never touched. `partial`: the body is the
    start of a cut-off chunk; stop quietly at the first incomplete record. Otherwise damage
    raises LogReadError naming the chunk's `offset` and the offset in the chunk.
    """
    cursor = _PieceCursor(pieces)
    index = 0
    for pos, buf, at, hlen, data_at, dlen in _records(cursor, offset, partial=partial):
        conn_id = -1
        op = 0
        if hlen == _MSG_HEAD_BYTES:
            # The usual message header in one unpack (either field order); anything else
            # (other fields, another order) is parsed field by field below.
            (n1, k1, op, n2, k2, conn_id, n3, k3, sec, nsec) = _MSG_OP_FIRST.unpack_from(buf, at)
            if not (n1 == 4 and k1 == b"op=" and n2 == 9 and k2 == b"conn=" and n3 == 13):
                (n1, k1, conn_id, n2, k2, op, n3, k3, sec, nsec) = _MSG_CONN_FIRST.unpack_from(
                    buf, at
                )
                if not (n1 == 9 and k1 == b"conn=" and n2 == 4 and k2 == b"op=" and n3 == 13):
                    conn_id = -1
            if k3 != b"time=":
                conn_id = -1
        if conn_id < 0:
            try:
                fields, op = _header(buf, at, hlen, offset, pos)
            except LogReadError:
                if partial:
                    return
                raise
            if op != OP_MSG_DATA:
                continue
            try:
                conn_id = _u32(fields, "conn")
                info = channels.get(conn_id)
                t = _time(fields, "time") if info is not None else 0
            except ValueError as exc:
                raise LogReadError(
                    f"ROS 1 chunk at byte {offset}: bad message record ({exc})"
                ) from None
        elif op != OP_MSG_DATA:
            continue
        else:
            info = channels.get(conn_id)
            t = sec * 1_000_000_000 + nsec
        if info is not None:
            wanted = dlen if info.prefix_bytes <= 0 else min(dlen, info.prefix_bytes)
            data, data_pos = cursor.at(data_at, wanted)
            yield t, index, conn_id, memoryview(data)[data_pos : data_pos + wanted]
        index += 1


HEAD_BYTES = 4096
"""Bytes read first of an lz4 chunk record: its header, the frame's descriptor and first
block size (a chunk header holds two short fields)."""


class Rosbag1ChunkReader:
    """Per-worker reader of 'rosbag1-chunk' units: one open file per source, reused.

    An lz4 chunk of a local file is read block by block (`lz4_frame`): blocks stored
    uncompressed (JPEG pixels: most of a camera bag) stay in the file, and only the record
    headers and wanted payloads in them are read (`pread`), so the bytes of images nobody
    looks at are neither copied nor mapped. Other chunks are read whole into one reused
    buffer (`preadv`) and decompressed from there.
    `source` (optional) is the file the worker will read (`logs.units` builds one reader per
    worker and file); units of other files are read too. `check_crc`: verify lz4 frames'
    block and content checksums (by decoding them whole with `lz4.frame`, which does).
    """

    def __init__(self, source: str | None = None, *, check_crc: bool = False) -> None:
        self._files: dict[str, BagFile] = {}
        self.check_crc = check_crc
        self._buffer = bytearray()
        """Chunk records are read into this one buffer (no allocation per chunk)."""
        del source  # files are opened when their first unit is read

    def messages(
        self, unit: ReadUnit, channels: dict[int, ChannelInfo]
    ) -> Iterator[tuple[int, int, int, bytes | memoryview]]:
        """(log_time_ns, index_in_unit, connection id, payload) of wanted messages, file order.

        A unit shorter than its chunk record is the chunk a recording was cut inside (the
        scan made it so): its complete messages are read. Damage raises LogReadError.
        """
        bag = self._files.get(unit.source)
        if bag is None:
            try:
                bag = open_bag_file(Path(unit.source))
            except OSError as exc:
                raise LogReadError(f"{unit.source}: cannot read: {one_line(exc)}") from exc
            self._files[unit.source] = bag
        try:
            pieces = self._lz4_in_place(bag, unit)
            partial = False
            if pieces is None:
                record = self._read(bag, unit.offset, unit.length)
                if len(record) < unit.length:
                    raise LogReadError(
                        f"ROS 1 chunk at byte {unit.offset} cut off ({len(record)} of "
                        f"{unit.length} bytes; file changed since it was opened?)"
                    )
                partial = _declared_length(record) > unit.length
                body = chunk_body(record, unit.offset, partial=partial)
                if isinstance(body, memoryview):
                    # An uncompressed chunk's payloads are views of the buffer: callers may
                    # hold them past the next unit (the serial merge does), so it is theirs.
                    self._buffer = bytearray()
                pieces = whole(body)
            yield from wanted_messages(pieces, channels, unit.offset, partial=partial)
        except LogReadError as exc:
            raise LogReadError(f"{unit.source}: {exc}") from None
        except (FrameError, OSError) as exc:  # the file shrank or failed under the reader
            raise LogReadError(
                f"{unit.source}: ROS 1 chunk at byte {unit.offset}: {one_line(exc)}"
            ) from None

    def _lz4_in_place(self, bag: BagFile, unit: ReadUnit) -> Pieces | None:
        """The records of a whole lz4 chunk of a local file, its stored blocks left in the
        file; None where the chunk is read whole instead (another compression, a chunk cut
        off or unreadable: the whole read reports it, `check_crc`, a file in memory)."""
        fileno = getattr(bag.handle, "fileno", None)
        if self.check_crc or fileno is None:
            return None
        fd = fileno()
        head = os.pread(fd, min(unit.length, HEAD_BYTES), unit.offset)
        if len(head) < 8:
            return None
        (hlen,) = _U32.unpack_from(head, 0)
        if 8 + hlen > len(head):
            return None
        (dlen,) = _U32.unpack_from(head, 4 + hlen)
        if 8 + hlen + dlen != unit.length or unit.offset + unit.length > os.fstat(fd).st_size:
            return None
        compression, size, _data = chunk_head(head, unit.offset, partial=True)
        if compression != "lz4":
            return None
        start = 8 + hlen
        source = FrameSource(fd=fd, offset=unit.offset + start, length=dlen, head=head[start:])
        try:
            return decode_frame(source, size)
        except FrameError as exc:
            raise LogReadError(
                f"ROS 1 chunk at byte {unit.offset}: lz4 data damaged: {exc}"
            ) from None

    def _read(self, bag: BagFile, offset: int, length: int) -> memoryview:
        """Up to `length` bytes at `offset`, read into the reused buffer (overwritten by
        the next unit's read unless an uncompressed chunk's payloads took it over)."""
        length = max(0, min(length, bag.size - offset))
        if offset < 0 or length == 0:
            return memoryview(b"")
        if len(self._buffer) < length:
            self._buffer = bytearray(length)  # views of the old one keep it alive
        view = memoryview(self._buffer)[:length]
        got = os.preadv(bag.handle.fileno(), [view], offset)
        return view[:got]

    def close(self) -> None:
        """Close the files opened so far."""
        for bag in self._files.values():
            bag.handle.close()
        self._files.clear()


def _declared_length(record: bytes | memoryview) -> int:
    """Length the chunk record says it has (header and data lengths), or 0 if unreadable."""
    if len(record) < 4:
        return 0
    (hlen,) = _U32.unpack_from(record, 0)
    if len(record) < 8 + hlen:
        return 0
    (dlen,) = _U32.unpack_from(record, 4 + hlen)
    return int(8 + hlen + dlen)
