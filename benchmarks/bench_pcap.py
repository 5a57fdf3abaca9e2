#!/usr/bin/env python
"""Benchmark of reading a 1 GB LiDAR capture (issue 25); prints its figures.

1. Builds (once, cached in `--cache-dir`) a classic pcap and a pcapng capture of at least
   `--size-gb` by repeating the real HDL-32E packets of
   ../shared/data/pcap/veloview_hdl32_monterey_first_100_packets.pcap (data and position
   packets), each repetition's capture times and sensor stamps moved on by the span of
   the original, so time runs on as in one long drive.
2. Runs each contender as a subprocess (page cache warmed first) and measures its wall
   time, CPU time (user + sys, from `os.wait4`) and peak RSS (`ru_maxrss`):
   - `records`: syncaudit's record parser reading every record (the floor of `info`);
   - `records+udp`: the same, every frame decoded to its UDP datagram;
   - `dpkt`, `dpkt+udp`: dpkt's pcap Reader over every record (and its Ethernet/IP/UDP);
   - `pcapng-lib`: python-pcapng's FileScanner over the pcapng version;
   - `info -j1`, `info`: `syncaudit info --json` on the capture, one and all cores.
   A library that is not installed is reported as such.

Run `python benchmarks/bench_pcap.py --help`. Figures: docs/reading.md.
"""

from __future__ import annotations

import argparse
import os
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
SOURCE = REPO.parent / "shared" / "data" / "pcap" / "veloview_hdl32_monterey_first_100_packets.pcap"
DEFAULT_CACHE = REPO / "benchmarks" / ".cache"
HOUR_US = 3_600_000_000

CONTENDERS: dict[str, str] = {
    "records": """
import os, sys
from syncaudit.logs.pcap.records import RecordStream, read_format
path = sys.argv[1]; size = os.path.getsize(path)
with open(path, "rb") as f:
    fmt = read_format(f, path, size)
    n = sum(1 for _ in RecordStream(f, path, size, fmt).iter_range(fmt.first_record, size))
print(n)
""",
    "records+udp": """
import os, sys
from syncaudit.logs.pcap.records import RecordStream, read_format
from syncaudit.logs.pcap.udp import UdpDecoder
path = sys.argv[1]; size = os.path.getsize(path); udp = UdpDecoder(); n = 0
with open(path, "rb") as f:
    fmt = read_format(f, path, size)
    for r in RecordStream(f, path, size, fmt).iter_range(fmt.first_record, size):
        n += udp.datagram(r.data, r.link_type) is not None
print(n)
""",
    "dpkt": """
import sys, dpkt
with open(sys.argv[1], "rb") as f:
    print(sum(1 for _ in dpkt.pcap.Reader(f)))
""",
    "dpkt+udp": """
import sys, dpkt
n = 0
with open(sys.argv[1], "rb") as f:
    for ts, buf in dpkt.pcap.Reader(f):
        ip = dpkt.ethernet.Ethernet(buf).data
        n += isinstance(ip.data, dpkt.udp.UDP)
print(n)
""",
    "pcapng-lib": """
import sys
from pcapng import FileScanner
from pcapng.blocks import EnhancedPacket
with open(sys.argv[1], "rb") as f:
    print(sum(1 for b in FileScanner(f) if isinstance(b, EnhancedPacket)))
""",
}


def build(out: Path, size_bytes: int, ng: bool) -> None:
    """Repeat the source capture's records until `size_bytes`, times moved on each time."""
    raw = SOURCE.read_bytes()
    records = []
    pos = 24
    while pos + 16 <= len(raw):
        sec, usec, incl, _orig = struct.unpack_from("<IIII", raw, pos)
        records.append((sec * 1_000_000 + usec, bytearray(raw[pos + 16 : pos + 16 + incl])))
        pos += 16 + incl
    first, last = records[0][0], records[-1][0]
    span_us = last - first + (last - first) // len(records)
    tmp = out.with_suffix(".part")
    with tmp.open("wb") as f:
        if ng:
            f.write(_block(0x0A0D0D0A, struct.pack("<IHHq", 0x1A2B3C4D, 1, 0, -1)))
            f.write(_block(1, struct.pack("<HHI", 1, 0, 65535)))
        else:
            f.write(struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 65535, 1))
        k = 0
        while f.tell() < size_bytes:
            shift = k * span_us
            for t_us, frame in records:
                data = frame
                if len(frame) == 1248:  # Velodyne data: move the sensor stamp on too
                    data = bytearray(frame)
                    (toh,) = struct.unpack_from("<I", data, 42 + 1200)
                    struct.pack_into("<I", data, 42 + 1200, (toh + shift) % HOUR_US)
                t = t_us + shift
                if ng:
                    body = struct.pack("<IIIII", 0, t >> 32, t & 0xFFFFFFFF, len(data), len(data))
                    f.write(_block(6, body + bytes(data) + b"\0" * (-len(data) % 4)))
                else:
                    f.write(
                        struct.pack("<IIII", t // 1_000_000, t % 1_000_000, len(data), len(data))
                    )
                    f.write(data)
            k += 1
    tmp.replace(out)


def _block(btype: int, body: bytes) -> bytes:
    total = 12 + len(body)
    return struct.pack("<II", btype, total) + body + struct.pack("<I", total)


def measure(argv: list[str]) -> tuple[float, float, float, str]:
    """(wall s, cpu s, peak RSS MiB, last output line) of one subprocess."""
    with tempfile.TemporaryFile() as errors:
        start = time.perf_counter()
        proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=errors)
        assert proc.stdout is not None
        out = proc.stdout.read()
        _pid, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - start
        proc.returncode = os.waitstatus_to_exitcode(status)
        errors.seek(0)
        err = errors.read().decode(errors="replace").strip().splitlines()
    lines = out.decode(errors="replace").strip().splitlines()
    tail = lines[-1][:80] if lines else ""
    if proc.returncode:
        tail = "FAILED: " + (err[-1][:80] if err else "?")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024, tail


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawTextHelpFormatter
    )
    parser.add_argument("--size-gb", type=float, default=1.0)
    parser.add_argument("--cache-dir", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--only", nargs="*", help="contenders to run (default: all)")
    args = parser.parse_args()
    args.cache_dir.mkdir(parents=True, exist_ok=True)
    size = int(args.size_gb * 1024**3)
    pcap = args.cache_dir / f"hdl32_{args.size_gb:g}gb.pcap"
    pcapng = args.cache_dir / f"hdl32_{args.size_gb:g}gb.pcapng"
    for path, ng in ((pcap, False), (pcapng, True)):
        if not path.exists():
            t0 = time.perf_counter()
            build(path, size, ng)
            print(
                f"built {path} ({path.stat().st_size / 1e9:.2f} GB) in {time.perf_counter() - t0:.0f} s"
            )
    for path in (pcap, pcapng):
        with path.open("rb") as f:
            while f.read(1024 * 1024):  # small reads: the children's RSS starts from ours
                pass
    runs: list[tuple[str, list[str]]] = []
    for name, code in CONTENDERS.items():
        target = pcapng if name == "pcapng-lib" else pcap
        runs.append((name, [sys.executable, "-c", code, str(target)]))
    cli = [sys.executable, "-m", "syncaudit", "info", "--json"]
    runs.append(("info", [*cli, str(pcap)]))
    runs.append(("info pcapng", [*cli, str(pcapng)]))
    print(f"{'contender':<14} {'wall s':>8} {'cpu s':>8} {'MB/s':>8} {'peak MiB':>9}  output")
    for name, argv in runs:
        if args.only and name not in args.only:
            continue
        wall, cpu, rss, tail = measure(argv)
        mbps = pcap.stat().st_size / 1e6 / wall
        if "No module named" in tail:
            tail = "not installed"
        print(f"{name:<14} {wall:8.2f} {cpu:8.2f} {mbps:8.0f} {rss:9.0f}  {tail}")


if __name__ == "__main__":
    main()
