"""Capture formats, link layers, fragments, cuts and hostile files: the real HDL-32E packets
rewritten every way a capture may hold them give the same `info`."""

from __future__ import annotations

import dataclasses
import itertools
from pathlib import Path

import pytest

from pcap_writer import Datagram, write_capture
from syncaudit.audit.inspect import LidarRow, inspect_log
from syncaudit.errors import LogOpenError, LogReadError
from syncaudit.logs import open_log
from syncaudit.logs.pcap import reader as pcap_reader
from syncaudit.logs.pcap import records
from syncaudit.logs.pcap.udp import UdpDecoder

HDL32 = "rlu_hdl32_example.pcap"


@pytest.fixture(scope="module")
def datagrams(pcap_data: Path) -> list[Datagram]:
    """The example's UDP payloads with their capture times."""
    path = pcap_data / HDL32
    with path.open("rb") as handle:
        size = path.stat().st_size
        fmt = records.read_format(handle, str(path), size)
        stream = records.RecordStream(handle, str(path), size, fmt)
        udp = UdpDecoder()
        out = []
        for record in stream.iter_range(fmt.first_record, size):
            d = udp.datagram(record.data, record.link_type)
            assert d is not None
            out.append(Datagram(record.time_ns, d.payload, d.port, d.source))
    assert len(out) == 976
    return out


@pytest.fixture(scope="module")
def reference(pcap_data: Path) -> LidarRow:
    (row,) = inspect_log(pcap_data / HDL32, jobs=1).lidars
    return row


def _row(path: Path, jobs: int = 1) -> LidarRow:
    (row,) = inspect_log(path, jobs=jobs).lidars
    return row


VARIANTS = {
    "pcap-le-us-ether": {},
    "pcap-be-ns-ether": {"big_endian": True, "nanoseconds": True},
    "pcap-vlan-qinq": {"vlans": 2},
    "pcap-sll": {"link": "sll"},
    "pcap-sll2": {"link": "sll2"},
    "pcap-raw-ip": {"link": "raw"},
    "pcap-fragments": {"mtu": 576},
    "pcapng-le-us": {"ng": True},
    "pcapng-be-ns-sll2": {"ng": True, "big_endian": True, "nanoseconds": True, "link": "sll2"},
    "pcapng-fragments": {"ng": True, "mtu": 400},
}


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_every_format_gives_the_same_info(
    tmp_path: Path, datagrams: list[Datagram], reference: LidarRow, variant: str
) -> None:
    path = tmp_path / f"{variant}.pcap"
    path.write_bytes(write_capture(datagrams, **VARIANTS[variant]))  # type: ignore[arg-type]
    row = _row(path)
    assert dataclasses.replace(row, topic=reference.topic) == reference
    with open_log(path) as log:
        (position,) = [t for t in log.topics.values() if t.name.endswith("position_packets")]
        assert position.count == 100
        assert log.summary.container == ("pcapng" if "pcapng" in variant else "pcap")


def test_two_sensors_are_kept_apart_by_source(tmp_path: Path, datagrams: list[Datagram]) -> None:
    other = [dataclasses.replace(d, source="192.168.1.202") for d in datagrams]
    merged = sorted(datagrams + other, key=lambda d: d.time_ns)
    path = tmp_path / "two.pcap"
    path.write_bytes(write_capture(merged))
    report = inspect_log(path, jobs=1)
    assert [r.topic for r in report.lidars] == [
        "/pcap/192_168_1_201_2368/velodyne_packets",
        "/pcap/192_168_1_202_2368/velodyne_packets",
    ]
    assert [r.packets for r in report.lidars] == [876, 876]


def test_parallel_ranges_read_as_the_serial_path(
    tmp_path: Path, datagrams: list[Datagram], monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "ranges.pcap"
    path.write_bytes(write_capture(datagrams))
    serial = _row(path)
    monkeypatch.setattr(pcap_reader, "UNIT_BYTES", 64 * 1024)
    with open_log(path) as log:
        units = log.read_units(frozenset(log.topics))
        assert units is not None and len(units) > 10
        assert all(a.offset + a.length == b.offset for a, b in itertools.pairwise(units))
        topic = next(t for t in log.topics if t.endswith("velodyne_packets"))
        assert sum(1 for _ in log.messages(topic)) == log.topics[topic].count
    chunked = _row(path)
    parallel = _row(path, jobs=2)
    assert parallel == chunked
    assert (chunked.packets, chunked.revolutions, chunked.rpm) == (
        serial.packets,
        serial.revolutions,
        pytest.approx(serial.rpm, rel=1e-9),
    )


def test_a_cut_capture_is_read_to_the_cut(tmp_path: Path, datagrams: list[Datagram]) -> None:
    raw = write_capture(datagrams)
    path = tmp_path / "cut.pcap"
    path.write_bytes(raw[: len(raw) - 700])  # inside the last record
    with open_log(path) as log:
        assert any(w.code == "truncated" for w in log.warnings)
    report = inspect_log(path, jobs=1)
    assert any("capture cut at byte" in w for w in report.warnings)
    assert report.lidars[0].packets in (875, 876)


def _hostile(tmp_path: Path, datagrams: list[Datagram], **changes: int) -> Path:
    raw = bytearray(write_capture(datagrams[:20]))
    if "snaplen" in changes:
        raw[16:20] = changes["snaplen"].to_bytes(4, "little")
    if "record_len" in changes:
        raw[24 + 8 : 24 + 12] = changes["record_len"].to_bytes(4, "little")
    path = tmp_path / "hostile.pcap"
    path.write_bytes(bytes(raw))
    return path


def test_snap_length_zero_is_refused(tmp_path: Path, datagrams: list[Datagram]) -> None:
    with pytest.raises(LogOpenError, match="snap length is 0"):
        open_log(_hostile(tmp_path, datagrams, snaplen=0))


def test_a_record_past_the_snap_length_is_refused(
    tmp_path: Path, datagrams: list[Datagram]
) -> None:
    with pytest.raises(LogReadError, match="past the snap length") as err:
        open_log(_hostile(tmp_path, datagrams, record_len=0x7FFFFFF0))
    assert "\n" not in str(err.value)


def test_too_many_records_are_refused(
    tmp_path: Path, datagrams: list[Datagram], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(records, "MAX_RECORDS", 10)
    with pytest.raises(LogReadError, match="more than 2\\^32 - 1 records"):
        open_log(_hostile(tmp_path, datagrams))


def test_not_a_capture_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "x.pcap"
    path.write_bytes(b"\x0a\x0d\x0d\x0a\x1c\x00\x00\x00\x00\x00\x00\x00")
    with pytest.raises(LogOpenError, match="byte-order magic"):
        open_log(path)


def test_fragments_across_range_ends_are_read_once(
    tmp_path: Path, datagrams: list[Datagram], monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "fragments.pcap"
    path.write_bytes(write_capture(datagrams, mtu=256))  # 5-6 fragments per packet
    whole = _row(path)
    monkeypatch.setattr(pcap_reader, "UNIT_BYTES", 16 * 1024)
    with open_log(path) as log:
        assert len(log.read_units(frozenset(log.topics)) or []) > 50
    chunked = _row(path)
    assert chunked.scans > whole.scans  # scan messages end with each range
    assert dataclasses.replace(chunked, scans=whole.scans) == whole
    assert _row(path, jobs=2) == chunked
    assert (whole.packets, whole.dropped_packets) == (876, 0)


def test_pcapng_interfaces_described_late_are_read_in_order(
    tmp_path: Path, datagrams: list[Datagram], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A second interface block after the first packets: read serially, packets counted."""
    import struct

    raw = bytearray(write_capture(datagrams, ng=True))
    idb = struct.pack("<IIHHI", 1, 20, 1, 0, 65535) + struct.pack("<I", 20)
    first_epb = raw.index(struct.pack("<I", 6))  # section + interface blocks come first
    cut = first_epb + int.from_bytes(raw[first_epb + 4 : first_epb + 8], "little")
    raw[cut:cut] = idb
    path = tmp_path / "late.pcapng"
    path.write_bytes(bytes(raw))
    monkeypatch.setattr(pcap_reader, "UNIT_BYTES", 64 * 1024)
    with open_log(path) as log:
        assert log.read_units(frozenset(log.topics)) is None
        topic = next(t for t in log.topics if t.endswith("velodyne_packets"))
        assert sum(1 for _ in log.messages(topic)) == log.topics[topic].count
    assert _row(path).packets == 876
