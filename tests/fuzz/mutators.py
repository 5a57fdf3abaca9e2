"""Mutators for MCAP, ROS 2 `.db3`, ROS 1 `.bag` and rig files, each a pure function of a seed.

Byte-level mutators parse the container's own record framing (MCAP: opcode u8, length
u64; ROS 1: header length u32, header fields, data length u32, data) so truncations hit
every record-boundary class and hostile lengths land in real length fields. Semantic
mutators rewrite an MCAP with the `mcap` library (bad message encodings, payloads cut
or bit-flipped, log times past 2^63) or a `.db3` with sqlite3. Each returns a one-line
description; with the base name, mutator and seed it replays the mutant exactly.
"""

from __future__ import annotations

import random
import shutil
import sqlite3
import struct
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

MCAP_MAGIC = b"\x89MCAP0\r\n"
ROSBAG_MAGIC = b"#ROSBAG V2.0\n"
MCAP_OPCODES = {
    0x01: "header",
    0x02: "footer",
    0x03: "schema",
    0x04: "channel",
    0x05: "message",
    0x06: "chunk",
    0x07: "message_index",
    0x08: "chunk_index",
    0x09: "attachment",
    0x0A: "attachment_index",
    0x0B: "statistics",
    0x0C: "metadata",
    0x0D: "metadata_index",
    0x0E: "summary_offset",
    0x0F: "data_end",
}
BAG_OPS = {
    0x02: "message_data",
    0x03: "bag_header",
    0x04: "index_data",
    0x05: "chunk",
    0x06: "chunk_info",
    0x07: "connection",
}
HOSTILE_U64 = (0, 1, 7, 2**31, 2**32 - 1, 3_000_000_000, 2**40, 2**63, 2**64 - 1)
HOSTILE_U32 = (0, 1, 3, 2**16, 2**31 - 1, 2**31, 2**32 - 1)
BAD_ENCODINGS = ("protobuf", "json", "cdr2", "", "CDR", "ros2msg")
CUT_LENGTHS = (0, 1, 3, 4, 7, 8, 12, 13, 20, 40)


@dataclass(frozen=True, slots=True)
class Record:
    """One framed record of a container: where it starts, its class, its total size."""

    offset: int
    kind: str
    size: int
    length_offset: int
    """Offset of its length field (MCAP: u64 content length; ROS 1: u32 data length)."""


def mcap_records(data: bytes) -> list[Record]:
    """Every top-level record of an MCAP file in order (stops at the first bad framing)."""
    out: list[Record] = []
    pos = len(MCAP_MAGIC)
    while pos + 9 <= len(data):
        op = data[pos]
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        if op not in MCAP_OPCODES or pos + 9 + length > len(data):
            break
        out.append(Record(pos, MCAP_OPCODES[op], 9 + length, pos + 1))
        pos += 9 + length
    return out


def bag_records(data: bytes) -> list[Record]:
    """Every top-level record of a ROS 1 bag in order (chunks are not descended into)."""
    out: list[Record] = []
    pos = len(ROSBAG_MAGIC)
    while pos + 8 <= len(data):
        (header_len,) = struct.unpack_from("<I", data, pos)
        header = data[pos + 4 : pos + 4 + header_len]
        op = _bag_op(header)
        data_at = pos + 4 + header_len
        if op is None or data_at + 4 > len(data):
            break
        (data_len,) = struct.unpack_from("<I", data, data_at)
        out.append(Record(pos, BAG_OPS.get(op, f"op{op}"), 8 + header_len + data_len, data_at))
        pos += 8 + header_len + data_len
    return out


def _bag_op(header: bytes) -> int | None:
    i = 0
    while i + 4 <= len(header):
        (n,) = struct.unpack_from("<I", header, i)
        key, _, value = header[i + 4 : i + 4 + n].partition(b"=")
        if key == b"op" and value:
            return value[0]
        i += 4 + n
    return None


# ---- byte-level ---------------------------------------------------------------------------


def truncate_at_record(data: bytes, records: list[Record], rng: random.Random) -> tuple[bytes, str]:
    """Cut the file at the start, just inside, the middle or the last byte of a record."""
    kinds = sorted({r.kind for r in records})
    kind = rng.choice(kinds)
    rec = rng.choice([r for r in records if r.kind == kind])
    where = rng.choice(("start", "start+1", "middle", "end-1"))
    cut = {
        "start": rec.offset,
        "start+1": rec.offset + 1,
        "middle": rec.offset + rec.size // 2,
        "end-1": rec.offset + rec.size - 1,
    }[where]
    return data[
        :cut
    ], f"truncated at {where} of a {kind} record (offset {rec.offset}) -> {cut} bytes"


def truncate_anywhere(data: bytes, rng: random.Random) -> tuple[bytes, str]:
    """Cut the file at a random byte (a crash or a full disk)."""
    cut = rng.randrange(0, len(data))
    return data[:cut], f"truncated at byte {cut} of {len(data)}"


def flip_bits(
    data: bytes, rng: random.Random, *, start: int = 0, end: int | None = None, flips: int = 0
) -> tuple[bytes, str]:
    """Flip 1-16 random bits between `start` and `end`."""
    end = len(data) if end is None else end
    count = flips or rng.randint(1, 16)
    out = bytearray(data)
    where = sorted(rng.randrange(start, end) for _ in range(count))
    for pos in where:
        out[pos] ^= 1 << rng.randrange(8)
    shown = ",".join(str(p) for p in where[:6]) + ("..." if len(where) > 6 else "")
    return bytes(out), f"{count} bit flips at {shown}"


def hostile_length(
    data: bytes, records: list[Record], rng: random.Random, *, u64: bool
) -> tuple[bytes, str]:
    """A record's length field set to a hostile value (0, 2^31, 2^63, 2^64-1, ...)."""
    rec = rng.choice(records)
    value = rng.choice(HOSTILE_U64 if u64 else HOSTILE_U32)
    out = bytearray(data)
    struct.pack_into("<Q" if u64 else "<I", out, rec.length_offset, value)
    return bytes(out), f"length of a {rec.kind} record (offset {rec.offset}) set to {value}"


def hostile_chunk_field(
    data: bytes, records: list[Record], rng: random.Random
) -> tuple[bytes, str]:
    """An MCAP chunk's uncompressed size, records length, times or compression name hostile."""
    chunks = [r for r in records if r.kind == "chunk"]
    rec = rng.choice(chunks)
    body = rec.offset + 9
    (name_len,) = struct.unpack_from("<I", data, body + 28)
    records_len_at = body + 32 + name_len
    out = bytearray(data)
    field = rng.choice(
        ("uncompressed_size", "records_length", "start_time", "end_time", "crc", "compression")
    )
    if field == "compression":
        name = rng.choice((b"zstd", b"lz4", b"", b"gzip", b"bz2"))
        old = data[body + 32 : body + 32 + name_len]
        if len(name) != len(old):
            name = (name + b"\0" * len(old))[: len(old)]
        out[body + 32 : body + 32 + name_len] = name
        return bytes(out), f"chunk at {rec.offset}: compression {old!r} -> {name!r}"
    at = {
        "uncompressed_size": body + 16,
        "records_length": records_len_at,
        "start_time": body,
        "end_time": body + 8,
        "crc": body + 24,
    }[field]
    if field == "crc":
        value = rng.randrange(2**32)
        struct.pack_into("<I", out, at, value)
    else:
        value = rng.choice(HOSTILE_U64)
        struct.pack_into("<Q", out, at, value)
    return bytes(out), f"chunk at {rec.offset}: {field} set to {value}"


# ---- semantic MCAP rewrites ---------------------------------------------------------------

TopicPick = Callable[[str, str], bool]
TOPIC_CLASSES: dict[str, TopicPick] = {
    "lidar": lambda topic, msgtype: "Scan" in msgtype or "Packet" in msgtype,
    "image": lambda topic, msgtype: msgtype.endswith(("/Image", "/CompressedImage")),
    "exposure": lambda topic, msgtype: msgtype.endswith(("/CameraExposure", "/ImageMetaData")),
    "trigger": lambda topic, msgtype: msgtype.endswith(("/TriggerEvent", "/TimeReference")),
    "tf_static": lambda topic, msgtype: topic == "/tf_static",
}


def rewrite_mcap(
    src: Path,
    dst: Path,
    *,
    encoding_of: Callable[[str, str, str], str] | None = None,
    payload_of: Callable[[str, str, int, bytes], bytes] | None = None,
    time_of: Callable[[str, int, int], int] | None = None,
    compression: str = "zstd",
) -> None:
    """Copy an MCAP message by message, changing channel encodings, payloads or log times."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    with src.open("rb") as f_in, dst.open("wb") as f_out:
        reader = make_reader(f_in)
        writer = Writer(f_out, compression=CompressionType[compression.upper()])
        writer.start(profile=reader.get_header().profile, library="syncaudit-fuzz")
        schema_ids: dict[int, int] = {}
        channel_ids: dict[int, int] = {}
        for index, (schema, channel, message) in enumerate(reader.iter_messages()):
            msgtype = schema.name if schema else ""
            if channel.id not in channel_ids:
                if schema is not None and schema.id not in schema_ids:
                    schema_ids[schema.id] = writer.register_schema(
                        schema.name, schema.encoding, schema.data
                    )
                encoding = channel.message_encoding
                if encoding_of is not None:
                    encoding = encoding_of(channel.topic, msgtype, encoding)
                channel_ids[channel.id] = writer.register_channel(
                    channel.topic,
                    encoding,
                    schema_ids[schema.id] if schema else 0,
                    dict(channel.metadata),
                )
            data = bytes(message.data)
            if payload_of is not None:
                data = payload_of(channel.topic, msgtype, index, data)
            log_time = message.log_time
            if time_of is not None:
                log_time = time_of(channel.topic, index, log_time)
            writer.add_message(
                channel_ids[channel.id],
                log_time=log_time,
                data=data,
                publish_time=min(message.publish_time, log_time),
                sequence=message.sequence,
            )
        writer.finish()


def mcap_topics(path: Path) -> list[tuple[str, str]]:
    """(topic, message type) of every channel of an MCAP."""
    from mcap.reader import make_reader

    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return sorted(
        (c.topic, summary.schemas[c.schema_id].name if c.schema_id in summary.schemas else "")
        for c in summary.channels.values()
    )


def pick_topic(topics: list[tuple[str, str]], rng: random.Random) -> tuple[str, str]:
    """A topic class and one of its topics (classes the log lacks are skipped)."""
    classes = [c for c, pick in TOPIC_CLASSES.items() if any(pick(t, m) for t, m in topics)]
    cls = rng.choice(classes)
    topic = rng.choice([t for t, m in topics if TOPIC_CLASSES[cls](t, m)])
    return cls, topic


def cut_payload(data: bytes, rng: random.Random) -> bytes:
    """A payload cut to a hostile length: empty, inside the header, or short by a few bytes."""
    choice = rng.choice((*CUT_LENGTHS, -1, -2, -5))
    return data[:choice] if choice >= 0 else data[: max(0, len(data) + choice)]


# ---- .db3 ---------------------------------------------------------------------------------


def db3_file(bag_dir: Path) -> Path:
    """The sqlite file of a rosbag2 directory."""
    (path,) = sorted(bag_dir.glob("*.db3"))
    return path


def db3_sql(bag_dir: Path, statements: list[tuple[str, tuple[object, ...]]]) -> None:
    """Run SQL on the copy of a bag (the mutation is the statements)."""
    con = sqlite3.connect(db3_file(bag_dir))
    try:
        for sql, args in statements:
            con.execute(sql, args)
        con.commit()
    finally:
        con.close()


def db3_topics(bag_dir: Path) -> list[tuple[int, str, str]]:
    """(id, name, type) of every topic of a `.db3` bag."""
    con = sqlite3.connect(db3_file(bag_dir))
    try:
        rows = con.execute("SELECT id, name, type FROM topics ORDER BY id").fetchall()
    finally:
        con.close()
    return [(int(i), str(n), str(t)) for i, n, t in rows]


def copy_log(src: Path, dst: Path) -> None:
    """Copy a log file or bag directory."""
    if src.is_dir():
        shutil.copytree(src, dst)
    else:
        shutil.copyfile(src, dst)
