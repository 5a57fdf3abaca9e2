"""MCAP files built with the `mcap` writer: encodings, no summary, truncation, corruption."""

from __future__ import annotations

import random
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Chunk
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, IndexType, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from syncaudit.errors import LogOpenError, LogReadError, UnknownTypeError
from syncaudit.logs import LogReader, open_log
from syncaudit.logs.typesys import schemas_dir

Untouched = Callable[[Path], Path]


@dataclass(frozen=True)
class Channel:
    """One MCAP channel to write: topic, schema and encodings."""

    topic: str
    schema_name: str
    schema_encoding: str = "ros2msg"
    schema_text: str = ""
    message_encoding: str = "cdr"


@dataclass(frozen=True)
class Written:
    """A message as written: topic, log time and serialized bytes."""

    topic: str
    log_time: int
    data: bytes


def write_mcap(
    path: Path, channels: list[Channel], messages: Iterable[Written], **writer_args: Any
) -> list[Written]:
    """Write an MCAP with the `mcap` writer; returns the messages in write order."""
    written = list(messages)
    writer_args.setdefault("compression", CompressionType.ZSTD)
    with path.open("wb") as handle:
        writer = Writer(handle, **writer_args)
        writer.start(profile="ros2", library="syncaudit-tests")
        ids: dict[str, int] = {}
        for ch in channels:
            schema_id = 0
            if ch.schema_name:
                schema_id = writer.register_schema(
                    ch.schema_name, ch.schema_encoding, ch.schema_text.encode()
                )
            ids[ch.topic] = writer.register_channel(ch.topic, ch.message_encoding, schema_id)
        for seq, msg in enumerate(written):
            writer.add_message(
                ids[msg.topic],
                log_time=msg.log_time,
                data=msg.data,
                publish_time=msg.log_time,
                sequence=seq,
            )
        writer.finish()
    return written


def pair(probe: Any) -> list[Channel]:
    """The /probe and /other channels, both of the probe type with its definition."""
    return [Channel(t, probe.type, "ros2msg", probe.definition) for t in ("/probe", "/other")]


NO_SUMMARY: dict[str, Any] = {
    "use_summary_offsets": False,
    "use_statistics": False,
    "repeat_channels": False,
    "repeat_schemas": False,
    "index_types": IndexType.NONE,
}


def probes(probe: Any, n: int, t0: int = 1_000, dt: int = 10) -> list[Written]:
    """n probe messages alternating /probe and /other, log times t0, t0+dt, ..."""
    topics = ("/probe", "/other")
    return [Written(topics[i % 2], t0 + i * dt, probe.make(i)) for i in range(n)]


def stream(log: LogReader, *args: Any) -> list[tuple[str, int, bytes]]:
    return [(m.topic, m.log_time_ns, bytes(m.data)) for m in log.messages(*args)]


def as_tuples(msgs: list[Written]) -> list[tuple[str, int, bytes]]:
    return [(m.topic, m.log_time, m.data) for m in msgs]


def test_ros2msg_cdr_channels(
    tmp_path: Path,
    ros2_store: Typestore,
    probe: Any,
    untouched: Untouched,
) -> None:
    imu_def, _ = ros2_store.generate_msgdef("sensor_msgs/msg/Imu", ros_version=2)
    imu_cls = ros2_store.types["sensor_msgs/msg/Imu"]
    header = ros2_store.types["std_msgs/msg/Header"]
    stamp = ros2_store.types["builtin_interfaces/msg/Time"]
    quat = ros2_store.types["geometry_msgs/msg/Quaternion"]
    vec = ros2_store.types["geometry_msgs/msg/Vector3"]
    imu = imu_cls(
        header=header(stamp=stamp(sec=7, nanosec=5), frame_id="imu_link"),
        orientation=quat(x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=np.zeros(9),
        angular_velocity=vec(x=0.1, y=0.2, z=0.3),
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=vec(x=0.0, y=0.0, z=9.81),
        linear_acceleration_covariance=np.zeros(9),
    )
    msgs = probes(probe, 20)
    msgs.insert(
        5,
        Written(
            "/imu",
            msgs[4].log_time + 1,
            bytes(ros2_store.serialize_cdr(imu, "sensor_msgs/msg/Imu")),
        ),
    )
    path = tmp_path / "ros2.mcap"
    write_mcap(
        path,
        [*pair(probe), Channel("/imu", "sensor_msgs/msg/Imu", "ros2msg", imu_def)],
        msgs,
        chunk_size=256,
    )
    untouched(path)

    with open_log(path) as log:
        s = log.summary
        assert (s.container, s.message_count, s.start_ns, s.end_ns) == ("mcap", 21, 1_000, 1_190)
        assert {
            n: (t.msgtype, t.encoding, t.count, t.has_definition) for n, t in log.topics.items()
        } == {
            "/probe": (probe.type, "cdr", 10, True),
            "/other": (probe.type, "cdr", 10, True),
            "/imu": ("sensor_msgs/msg/Imu", "cdr", 1, True),
        }
        assert stream(log) == as_tuples(msgs)
        assert stream(log, ["/probe"]) == as_tuples([m for m in msgs if m.topic == "/probe"])
        assert stream(log, None, 1_050, 1_100) == as_tuples(
            [m for m in msgs if 1_050 <= m.log_time < 1_100]
        )
        assert stream(log, ["/other", "/imu"], 1_041, 1_050) == [("/imu", 1_041, msgs[5].data)]

        raws = {m.topic: m for m in log.messages()}
        got: Any = log.deserialize(raws["/imu"])
        assert got.header.frame_id == "imu_link" and got.header.stamp.sec == 7
        assert got.linear_acceleration.z == pytest.approx(9.81)
        last_probe: Any = log.deserialize(raws["/probe"])
        assert (last_probe.seq, last_probe.label) == (18, "p18")
        assert log.warnings == []


def test_ros1msg_ros1_channels(tmp_path: Path, ros1_store: Typestore, untouched: Untouched) -> None:
    """ROS 1 schema names ('pkg/Name') and ROS 1 serialization, incl. ROS 1's Header.seq."""
    text, _md5 = ros1_store.generate_msgdef("geometry_msgs/msg/PointStamped", ros_version=1)
    cls = ros1_store.types["geometry_msgs/msg/PointStamped"]
    header = ros1_store.types["std_msgs/msg/Header"]
    stamp = ros1_store.types["builtin_interfaces/msg/Time"]
    point = ros1_store.types["geometry_msgs/msg/Point"]
    msgs = [
        Written(
            "/point",
            2_000 + i,
            bytes(
                ros1_store.serialize_ros1(
                    cls(
                        header=header(seq=40 + i, stamp=stamp(sec=i, nanosec=0), frame_id="map"),
                        point=point(x=i, y=0.5, z=-1.0),
                    ),
                    "geometry_msgs/msg/PointStamped",
                )
            ),
        )
        for i in range(6)
    ]
    path = tmp_path / "ros1.mcap"
    write_mcap(
        path, [Channel("/point", "geometry_msgs/PointStamped", "ros1msg", text, "ros1")], msgs
    )
    untouched(path)

    with open_log(path) as log:
        info = log.topics["/point"]
        assert (info.msgtype, info.encoding, info.count) == (
            "geometry_msgs/msg/PointStamped",
            "ros1",
            6,
        )
        raws = list(log.messages())
        assert [(m.msgtype, m.encoding) for m in raws] == [
            ("geometry_msgs/msg/PointStamped", "ros1")
        ] * 6
        got: Any = log.deserialize(raws[3])
        assert (got.header.seq, got.header.frame_id, got.point.x) == (43, "map", 3.0)


def test_log_definition_wins_over_schemas_dir(tmp_path: Path) -> None:
    """schemas/ has ouster_ros/PacketMsg as 'uint8[] buf'; the log's own definition is used."""
    text = "uint32 seq\nuint8[] buf\n"
    assert "uint32 seq" not in (schemas_dir() / "ouster_ros/msg/PacketMsg.msg").read_text()
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(text, "ouster_ros/msg/PacketMsg"))
    cls = store.types["ouster_ros/msg/PacketMsg"]
    data = bytes(
        store.serialize_cdr(cls(seq=77, buf=np.arange(4, dtype=np.uint8)), cls.__msgtype__)
    )
    path = tmp_path / "shadow.mcap"
    channel = Channel("/os/lidar_packets", "ouster_ros/msg/PacketMsg", "ros2msg", text)
    write_mcap(path, [channel], [Written(channel.topic, 5, data)])
    with open_log(path) as log:
        got: Any = log.deserialize(next(log.messages()))
    assert got.seq == 77 and list(got.buf) == [0, 1, 2, 3]


def test_no_summary_section_reads_linearly(
    tmp_path: Path, probe: Any, untouched: Untouched
) -> None:
    path = tmp_path / "nosummary.mcap"
    msgs = write_mcap(path, pair(probe), probes(probe, 60), chunk_size=300, **NO_SUMMARY)
    with path.open("rb") as handle:
        assert make_reader(handle).get_summary() is None  # the file really has none
    untouched(path)
    with open_log(path) as log:
        assert [w.code for w in log.warnings] == ["mcap-no-summary"]
        s = log.summary
        assert (s.message_count, s.start_ns, s.end_ns) == (60, 1_000, 1_590)
        assert {n: t.count for n, t in log.topics.items()} == {"/probe": 30, "/other": 30}
        assert stream(log) == as_tuples(msgs)
        assert stream(log, "/other", 1_100, 1_200) == as_tuples(
            [m for m in msgs if m.topic == "/other" and 1_100 <= m.log_time < 1_200]
        )
        got: Any = log.deserialize(next(log.messages()))
        assert got.label == "p0"


@pytest.mark.parametrize(
    "compression", [CompressionType.NONE, CompressionType.LZ4, CompressionType.ZSTD]
)
def test_truncated_mid_chunk_yields_complete_messages(
    tmp_path: Path,
    probe: Any,
    compression: CompressionType,
    untouched: Untouched,
) -> None:
    full = tmp_path / "full.mcap"
    msgs = write_mcap(
        full, pair(probe), probes(probe, 3000), chunk_size=40_000, compression=compression
    )
    data = full.read_bytes()
    with full.open("rb") as handle:
        summary = make_reader(handle).get_summary()
    assert summary is not None and len(summary.chunk_indexes) >= 4
    chunk = summary.chunk_indexes[2]
    cut = chunk.chunk_start_offset + chunk.chunk_length * 2 // 3  # inside the third chunk
    before = [c for c in summary.chunk_indexes if c.chunk_start_offset + c.chunk_length <= cut]
    in_whole_chunks = [m for m in msgs if m.log_time <= max(c.message_end_time for c in before)]
    path = tmp_path / "cut.mcap"
    path.write_bytes(data[:cut])
    untouched(path)

    with open_log(path) as log:
        assert "mcap-truncated" in [w.code for w in log.warnings]
        got = stream(log)
        assert log.summary.message_count == len(got)
        assert got == as_tuples(msgs[: len(got)])  # an exact, complete prefix
        assert len(in_whole_chunks) <= len(got) < len(msgs)
        if compression == CompressionType.NONE:
            # uncompressed: every message whose record ends before the cut is recovered
            complete = [m for m in msgs if data.find(m.data) + len(m.data) <= cut]
            assert len(got) == len(complete) > len(in_whole_chunks)


def test_truncated_out_of_order_chunks_merge_by_log_time(tmp_path: Path, probe: Any) -> None:
    """Without an index the reader merges chunks by time (recorders write slightly out of order)."""
    rng = random.Random(7)
    msgs = probes(probe, 400)
    for i in range(0, len(msgs) - 10, 10):  # shuffle within windows spanning chunk borders
        window = msgs[i : i + 15]
        rng.shuffle(window)
        msgs[i : i + 15] = window
    full = tmp_path / "full.mcap"
    write_mcap(full, pair(probe), msgs, chunk_size=500)
    data = full.read_bytes()
    path = tmp_path / "cut.mcap"
    path.write_bytes(data[: len(data) // 2])
    with open_log(path) as log:
        got = [(t, d) for _topic, t, d in stream(log)]
        assert got == sorted(got, key=lambda x: x[0]) and len(got) > 50
        assert set(got) <= {(m.log_time, m.data) for m in msgs}
        assert len(got) == log.summary.message_count
        window = [t for _topic, t, _ in stream(log, "/probe", 1_500, 2_000)]
        assert window == sorted(t for t, _ in got if 1_500 <= t < 2_000 and (t - 1_000) % 20 == 0)


def test_cut_inside_footer_keeps_all_messages_and_warns(tmp_path: Path, probe: Any) -> None:
    full = tmp_path / "full.mcap"
    msgs = write_mcap(full, pair(probe), probes(probe, 50), chunk_size=300)
    path = tmp_path / "cut.mcap"
    path.write_bytes(full.read_bytes()[:-12])
    with open_log(path) as log:
        assert [w.code for w in log.warnings] == ["mcap-truncated"]
        assert stream(log) == as_tuples(msgs)


@pytest.mark.parametrize("indexed", [True, False])
def test_corrupt_chunk_raises_log_read_error(
    tmp_path: Path,
    probe: Any,
    indexed: bool,
    untouched: Untouched,
) -> None:
    path = tmp_path / "corrupt.mcap"
    extra = {} if indexed else NO_SUMMARY
    write_mcap(path, pair(probe), probes(probe, 200), chunk_size=2_000, **extra)
    data = bytearray(path.read_bytes())
    # locate the third chunk by scanning records (works with and without an index)
    with path.open("rb") as handle:
        offsets = []
        reader = StreamReader(handle, emit_chunks=True)
        for record in reader.records:
            if isinstance(record, Chunk):
                offsets.append((handle.tell() - len(record.data), len(record.data)))
    start, size = offsets[2]
    for i in range(start + size // 3, start + size // 3 + 16):
        data[i] ^= 0x5A
    path.write_bytes(bytes(data))
    untouched(path)

    with pytest.raises(LogReadError) as info, open_log(path) as log:  # unindexed: fails here
        for _ in log.messages():  # indexed: reading the chunk fails
            pass
    text = str(info.value)
    assert info.value.exit_code == 3
    assert "\n" not in text and str(path) in text and "corrupt" in text


def test_unknown_types_fail_on_deserialize_but_stream_raw(tmp_path: Path, probe: Any) -> None:
    channels = [
        Channel("/noschema", ""),  # schema id 0
        Channel("/nodef", "mystery_msgs/msg/Thing", "ros2msg", ""),  # named, no text
        Channel("/json", "Thing", "jsonschema", '{"type": "object"}', "json"),
        Channel("/nested", "outer_msgs/msg/Outer", "ros2msg", "inner_msgs/Inner inner\n"),
    ]
    msgs = [
        Written("/noschema", 1, b"\x00\x01\x02"),
        Written("/nodef", 2, probe.make(1)),
        Written("/json", 3, b'{"a": 1}'),
        Written("/nested", 4, b"\x00\x01\x00\x00\x05\x00\x00\x00"),
    ]
    path = tmp_path / "unknown.mcap"
    write_mcap(path, channels, msgs)
    with open_log(path) as log:
        raws = list(log.messages())
        assert [(m.topic, bytes(m.data)) for m in raws] == [(m.topic, m.data) for m in msgs]
        assert [log.topics[c.topic].has_definition for c in channels] == [False, False, True, True]
        expected = ["'<no schema>'", "mystery_msgs/msg/Thing", "'json'", "inner_msgs/msg/Inner"]
        for raw, needle in zip(raws, expected, strict=True):
            with pytest.raises(UnknownTypeError) as info:
                log.deserialize(raw)
            assert needle in str(info.value) and "\n" not in str(info.value)
            assert info.value.exit_code == 4


def test_bytes_that_do_not_fit_the_definition_raise_log_read_error(
    tmp_path: Path, probe: Any
) -> None:
    path = tmp_path / "short.mcap"
    write_mcap(path, pair(probe)[:1], [Written("/probe", 1, b"\x00\x01\x00\x00\x05")])
    with open_log(path) as log, pytest.raises(LogReadError, match=probe.type):
        log.deserialize(next(log.messages()))


@pytest.mark.parametrize("kind", ["indexed", "no-summary"])
def test_empty_mcap(tmp_path: Path, probe: Any, kind: str) -> None:
    path = tmp_path / "empty.mcap"
    write_mcap(path, pair(probe)[:1], [], **({} if kind == "indexed" else NO_SUMMARY))
    with open_log(path) as log:
        s = log.summary
        assert (s.message_count, s.start_ns, s.end_ns, s.duration_s) == (0, None, None, None)
        if kind == "indexed":
            assert log.topics["/probe"].count == 0
        else:  # the writer keeps channel records in chunks, and an empty file has none
            assert log.topics == {}
        assert list(log.messages()) == []
        assert [w.code for w in log.warnings] == ([] if kind == "indexed" else ["mcap-no-summary"])


def test_mcap_without_channels(tmp_path: Path) -> None:
    path = tmp_path / "bare.mcap"
    write_mcap(path, [], [])
    with open_log(path) as log:
        assert (log.summary.message_count, log.topics, log.warnings) == (0, {}, [])


@pytest.mark.parametrize("shuffled", [False, True])
def test_unchunked_mcap(tmp_path: Path, probe: Any, shuffled: bool) -> None:
    """Unchunked files have no chunk index: read linearly; out of order is said, not hidden."""
    msgs = probes(probe, 30)
    if shuffled:
        msgs[3], msgs[20] = msgs[20], msgs[3]
    path = tmp_path / "unchunked.mcap"
    write_mcap(path, pair(probe), msgs, use_chunking=False)
    with open_log(path) as log:
        assert log.summary.message_count == 30
        assert stream(log) == as_tuples(msgs)  # file order
        assert [w.code for w in log.warnings] == (["mcap-unordered"] if shuffled else [])


def test_summary_without_statistics_uses_chunk_index_times(tmp_path: Path, probe: Any) -> None:
    path = tmp_path / "nostats.mcap"
    msgs = write_mcap(path, pair(probe), probes(probe, 40), chunk_size=300, use_statistics=False)
    with open_log(path) as log:
        s = log.summary
        assert (s.start_ns, s.end_ns, s.message_count) == (1_000, 1_390, 40)
        # issue 9 item 8: counted from the message indexes after each chunk
        expected: dict[str, int] = {}
        for m in msgs:
            expected[m.topic] = expected.get(m.topic, 0) + 1
        assert {n: t.count for n, t in log.topics.items()} == expected
        assert stream(log) == as_tuples(msgs) and log.warnings == []


@pytest.mark.parametrize("extra", [{}, NO_SUMMARY], ids=["indexed", "linear"])
def test_interleaved_generators_and_close(
    tmp_path: Path, probe: Any, extra: dict[str, Any]
) -> None:
    path = tmp_path / "two.mcap"
    msgs = write_mcap(path, pair(probe), probes(probe, 80), chunk_size=200, **extra)
    log = open_log(path)
    a, b = log.messages("/probe"), log.messages("/other")
    pairs = list(zip(a, b, strict=True))
    assert [x.log_time_ns for x, _ in pairs] == [m.log_time for m in msgs if m.topic == "/probe"]
    assert [y.log_time_ns for _, y in pairs] == [m.log_time for m in msgs if m.topic == "/other"]
    log.close()
    log.close()
    with pytest.raises(ValueError, match="closed"):
        log.messages()


def test_mcap_magic_with_garbage_is_an_open_error(tmp_path: Path) -> None:
    path = tmp_path / "garbage.mcap"
    path.write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)) * 4)
    with pytest.raises(LogOpenError, match="not a valid MCAP file") as info:
        open_log(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


IDL_TEXT = """module idl_probe_msgs {
  module msg {
    struct Reading {
      uint32 seq;
      string label;
    };
  };
};
"""


@pytest.mark.parametrize("sectioned", [True, False], ids=["rosbag2-sections", "plain"])
def test_ros2idl_schema(tmp_path: Path, sectioned: bool) -> None:
    """IDL definitions, as rosbag2 stores them ('====...\\nIDL: name\\n' per type) or bare."""
    name = "idl_probe_msgs/msg/Reading"
    text = f"{'=' * 80}\nIDL: {name}\n{IDL_TEXT}" if sectioned else IDL_TEXT
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg("uint32 seq\nstring label\n", name))
    data = bytes(store.serialize_cdr(store.types[name](seq=5, label="idl"), name))
    path = tmp_path / "idl.mcap"
    write_mcap(path, [Channel("/idl", name, "ros2idl", text)], [Written("/idl", 1, data)])
    with open_log(path) as log:
        got: Any = log.deserialize(next(log.messages()))
        assert (got.seq, got.label) == (5, "idl") and log.warnings == []


def test_unreadable_summary_falls_back_to_a_linear_scan(tmp_path: Path, probe: Any) -> None:
    path = tmp_path / "badsummary.mcap"
    msgs = write_mcap(path, pair(probe), probes(probe, 40), chunk_size=300)
    data = bytearray(path.read_bytes())
    footer = len(data) - 8 - 29  # Footer record: opcode, length, summary_start, ...
    assert data[footer] == 0x02
    data[footer + 9 : footer + 17] = (len(data) + 100).to_bytes(8, "little")  # past the end
    path.write_bytes(bytes(data))
    with open_log(path) as log:
        assert [w.code for w in log.warnings] == ["mcap-bad-summary"]
        assert log.summary.message_count == 40
        assert stream(log) == as_tuples(msgs)


def test_broken_file_in_schemas_dir_is_a_warning(
    tmp_path: Path, probe: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    """One unparseable .msg under schemas/ must not make every log unreadable."""
    import syncaudit.logs.typesys as typesys

    for pkg, text in [("good_msgs", "uint8 x\n"), ("bad_msgs", "uint8[ broken\n")]:
        (tmp_path / "schemas" / pkg / "msg").mkdir(parents=True)
        (tmp_path / "schemas" / pkg / "msg" / "Thing.msg").write_text(text)
    monkeypatch.setattr(typesys, "schemas_dir", lambda: tmp_path / "schemas")
    typesys._project_schemas.cache_clear()
    try:
        assert set(typesys.project_types()) == {"good_msgs/msg/Thing"}
        path = tmp_path / "log.mcap"
        write_mcap(path, pair(probe), probes(probe, 2))
        with open_log(path) as log:
            got: Any = log.deserialize(next(log.messages()))
            assert got.label == "p0"
            assert [(w.code, "bad_msgs/msg/Thing.msg" in w.message) for w in log.warnings] == [
                ("bad-project-schema", True)
            ]
    finally:
        typesys._project_schemas.cache_clear()
