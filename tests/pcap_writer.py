"""Write test captures: the UDP payloads given, in any of the formats and link types a
capture may use (classic or pcapng, either byte order, us or ns stamps, Ethernet with VLAN
tags, Linux cooked v1/v2, raw IPv4), IPv4-fragmented where asked."""

from __future__ import annotations

import struct
from collections.abc import Iterable
from dataclasses import dataclass


@dataclass(frozen=True)
class Datagram:
    time_ns: int
    payload: bytes
    port: int
    source: str = "192.168.1.201"


def _ipv4(src: str, udp: bytes, ident: int, frag_offset: int, more: bool) -> bytes:
    flags = (0x2000 if more else 0) | (frag_offset // 8)
    head = struct.pack(
        ">BBHHHBBH4s4s", 0x45, 0, 20 + len(udp), ident, flags, 64, 17, 0,
        bytes(int(x) for x in src.split(".")), bytes([192, 168, 1, 100]),
    )  # fmt: skip
    return head + udp


def ip_packets(d: Datagram, ident: int, mtu: int) -> list[bytes]:
    """The IPv4 packets of one datagram, fragmented to `mtu` bytes of IP payload (8-aligned)."""
    udp = struct.pack(">HHHH", 2368, d.port, 8 + len(d.payload), 0) + d.payload
    if len(udp) <= mtu:
        return [_ipv4(d.source, udp, ident, 0, False)]
    step = mtu // 8 * 8
    pieces = [udp[i : i + step] for i in range(0, len(udp), step)]
    return [
        _ipv4(d.source, piece, ident, k * step, k < len(pieces) - 1)
        for k, piece in enumerate(pieces)
    ]


def frame(ip: bytes, link: str, vlans: int = 0) -> bytes:
    """`ip` inside the link layer `link`: 'ether', 'sll', 'sll2' or 'raw'."""
    if link == "ether":
        tags = b"".join(struct.pack(">HH", 0x8100, 7) for _ in range(vlans))
        return b"\x11" * 6 + b"\x22" * 6 + tags + b"\x08\x00" + ip
    if link == "sll":
        return struct.pack(">HHH8sH", 0, 1, 6, b"\x22" * 8, 0x0800) + ip
    if link == "sll2":
        return struct.pack(">HHIHBB8s", 0x0800, 0, 2, 1, 0, 6, b"\x22" * 8) + ip
    return ip


LINK_TYPES = {"ether": 1, "sll": 113, "sll2": 276, "raw": 101}


def write_capture(
    datagrams: Iterable[Datagram],
    *,
    ng: bool = False,
    big_endian: bool = False,
    nanoseconds: bool = False,
    link: str = "ether",
    vlans: int = 0,
    mtu: int = 1480,
    snaplen: int = 65535,
) -> bytes:
    """The bytes of a capture holding `datagrams`."""
    e = ">" if big_endian else "<"
    frames = []
    for ident, d in enumerate(datagrams):
        for ip in ip_packets(d, ident & 0xFFFF, mtu):
            frames.append((d.time_ns, frame(ip, link, vlans)))
    link_type = LINK_TYPES[link]
    out = bytearray()
    if not ng:
        magic = 0xA1B23C4D if nanoseconds else 0xA1B2C3D4
        out += struct.pack(e + "IHHiIII", magic, 2, 4, 0, 0, snaplen, link_type)
        for time_ns, data in frames:
            sec, rest = divmod(time_ns, 1_000_000_000)
            sub = rest if nanoseconds else rest // 1000
            out += struct.pack(e + "IIII", sec, sub, len(data), len(data)) + data
        return bytes(out)
    out += _block(e, 0x0A0D0D0A, struct.pack(e + "IHHq", 0x1A2B3C4D, 1, 0, -1))
    options = b""
    if nanoseconds:
        options = struct.pack(e + "HH", 9, 1) + b"\x09\x00\x00\x00" + struct.pack(e + "HH", 0, 0)
    out += _block(e, 1, struct.pack(e + "HHI", link_type, 0, snaplen) + options)
    for time_ns, data in frames:
        ticks = time_ns if nanoseconds else time_ns // 1000
        body = struct.pack(e + "IIIII", 0, ticks >> 32, ticks & 0xFFFFFFFF, len(data), len(data))
        out += _block(e, 6, body + data + b"\x00" * (-len(data) % 4))
    return bytes(out)


def _block(e: str, btype: int, body: bytes) -> bytes:
    total = 12 + len(body)
    return struct.pack(e + "II", btype, total) + body + struct.pack(e + "I", total)
