"""UDP datagrams out of captured frames: link layers, VLAN tags, IPv4 and its fragments.

Link types (tcpdump's LINKTYPE_ numbers): 1 Ethernet (802.1Q / 802.1ad VLAN tags skipped),
113 Linux cooked (SLL), 276 Linux cooked v2 (SLL2), 101 / 228 / 12 / 14 raw IPv4, 0 BSD
loopback. IPv4 fragments are reassembled (a legacy Ouster packet of 128 beams is 24896 bytes,
17 Ethernet frames); what is not IPv4 UDP is counted, not read.
"""

from __future__ import annotations

import struct
from collections import OrderedDict
from dataclasses import dataclass, field

ETHERNET = 1
LINUX_SLL = 113
LINUX_SLL2 = 276
RAW_IP = (101, 228, 12, 14)
NULL_LOOPBACK = 0
LINK_TYPES = (ETHERNET, LINUX_SLL, LINUX_SLL2, NULL_LOOPBACK, *RAW_IP)
"""Link types read; others are counted as not IPv4."""

ETH_IPV4 = 0x0800
VLAN_TAGS = (0x8100, 0x88A8, 0x9100)
UDP = 17
MAX_PENDING_DATAGRAMS = 256
"""Fragmented datagrams kept while their other fragments are awaited (oldest dropped)."""


@dataclass(frozen=True, slots=True)
class Datagram:
    """One UDP datagram: its source address and ports, and payload."""

    source: str
    """Dotted IPv4 source address."""
    source_port: int
    port: int
    """Destination port."""
    payload: bytes


def ipv4_of(frame: bytes, link_type: int) -> bytes | None:
    """The IPv4 packet a captured frame carries (None: another protocol or link type)."""
    if link_type == ETHERNET:
        pos, ethertype = 12, -1
        while pos + 2 <= len(frame):
            ethertype = (frame[pos] << 8) | frame[pos + 1]
            if ethertype in VLAN_TAGS:
                pos += 4
                continue
            break
        return frame[pos + 2 :] if ethertype == ETH_IPV4 else None
    if link_type == LINUX_SLL:
        ok = len(frame) >= 16 and frame[14:16] == b"\x08\x00"
        return frame[16:] if ok else None
    if link_type == LINUX_SLL2:
        ok = len(frame) >= 20 and frame[0:2] == b"\x08\x00"
        return frame[20:] if ok else None
    if link_type == NULL_LOOPBACK:
        ok = len(frame) >= 4 and frame[0:4] in (b"\x02\x00\x00\x00", b"\x00\x00\x00\x02")
        return frame[4:] if ok else None
    if link_type in RAW_IP:
        return frame if frame[:1] and frame[0] >> 4 == 4 else None
    return None


@dataclass(slots=True)
class _Pending:
    pieces: dict[int, bytes] = field(default_factory=dict)
    total: int | None = None
    header: bytes = b""


@dataclass(slots=True)
class UdpDecoder:
    """Turns captured frames into UDP datagrams, reassembling IPv4 fragments; counts what
    it cannot read."""

    not_udp: int = 0
    """Frames that are not IPv4 UDP (ARP, IPv6, TCP, other link types)."""
    damaged: int = 0
    """IPv4 or UDP headers that contradict their lengths."""
    long_ip_lengths: int = 0
    """IPv4 headers claiming more bytes than their frame holds (read to the frame's end)."""
    dropped_fragments: int = 0
    """Fragmented datagrams never completed (a fragment lost, or cut off by the capture)."""
    _pending: OrderedDict[tuple[bytes, int], _Pending] = field(default_factory=OrderedDict)

    @property
    def awaiting(self) -> bool:
        """Whether fragmented datagrams await more fragments."""
        return bool(self._pending)

    def datagram(self, frame: bytes, link_type: int, *, new: bool = True) -> Datagram | None:
        """The datagram `frame` completes (None: a fragment awaiting others, or not UDP).

        A datagram's fragments are gathered from its first one (offset 0) on: a later
        fragment whose first was never seen belongs to a datagram begun before the range
        read, which the range before reads to its end. `new=False` (past a range's end)
        completes awaited datagrams only.
        """
        ip = ipv4_of(frame, link_type)
        if ip is None or len(ip) < 20 or ip[0] >> 4 != 4:
            self.not_udp += 1
            return None
        ihl = (ip[0] & 0x0F) * 4
        total = (ip[2] << 8) | ip[3]
        if ihl < 20 or total < ihl:
            self.damaged += 1
            return None
        if total > len(ip):
            # Early VLP-16 firmware writes 1234 as the IP length of its 554-byte position
            # frames; the UDP length, checked below, still bounds the datagram.
            self.long_ip_lengths += 1
            total = len(ip)
        if ip[9] != UDP:
            self.not_udp += 1
            return None
        flags_frag = (ip[6] << 8) | ip[7]
        more = bool(flags_frag & 0x2000)
        offset = (flags_frag & 0x1FFF) * 8
        body = ip[ihl:total]
        if not (more or offset or new):
            return None  # past the range: read by the next one
        if more or offset:
            whole = self._reassemble(ip, offset, more, body, new)
            if whole is None:
                return None
            body = whole
        return self._udp(ip, body)

    def _reassemble(
        self, ip: bytes, offset: int, more: bool, body: bytes, new: bool
    ) -> bytes | None:
        key = (ip[12:20], (ip[4] << 8) | ip[5])
        pending = self._pending.get(key)
        if pending is None:
            if offset or not new:
                return None
            pending = self._pending[key] = _Pending()
            if len(self._pending) > MAX_PENDING_DATAGRAMS:
                self._pending.popitem(last=False)
                self.dropped_fragments += 1
        pending.pieces[offset] = body
        if not more:
            pending.total = offset + len(body)
        if pending.total is None:
            return None
        covered, parts = 0, []
        for start in sorted(pending.pieces):
            if start != covered:
                return None
            parts.append(pending.pieces[start])
            covered += len(pending.pieces[start])
        if covered != pending.total:
            return None
        del self._pending[key]
        return b"".join(parts)

    def _udp(self, ip: bytes, body: bytes) -> Datagram | None:
        if len(body) < 8:
            self.damaged += 1
            return None
        sport, dport, length = struct.unpack(">HHH", body[:6])
        if length < 8 or length > len(body):
            self.damaged += 1
            return None
        source = ".".join(str(b) for b in ip[12:16])
        return Datagram(source, sport, dport, body[8:length])

    def finish(self) -> None:
        """Count the datagrams still awaiting fragments as dropped."""
        self.dropped_fragments += len(self._pending)
        self._pending.clear()
