"""Per-scan time of the audit's packet hot loop: decode_scan, then packet_samples.

    python benchmarks/bench_decode.py                    # cached 0.2 GB VLS-128 bench log
    python benchmarks/bench_decode.py LOG TOPIC [LOG TOPIC ...]

Any scan-message packet topic (Velodyne, PandarScan, NebulaPackets): the vendor family
comes from the topic's message type.

Scans are read once and copied into memory, then each step is timed per scan, `--repeat`
passes over all scans; the best pass is reported (the least disturbed by other load).
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path

from syncaudit.errors import SyncauditError
from syncaudit.lidar.samples import packet_samples
from syncaudit.lidar.stream import SCAN_TYPES, PacketChunk, decode_scan
from syncaudit.logs import RawMessage, open_log

HERE = Path(__file__).resolve().parent
DEFAULT_LOGS = "bench_0.2gb_x1_*.mcap"
"""The quick log bench_audit.py caches (`python benchmarks/bench_audit.py --quick`)."""
DEFAULT_TOPIC = "/velodyne_packets"


def read_scans(path: Path, topic: str) -> list[RawMessage]:
    """Every message on `topic`, its bytes copied (readers may reuse their buffers)."""
    with open_log(path) as log:
        return [
            RawMessage(m.topic, m.msgtype, m.log_time_ns, bytes(m.data), m.encoding)
            for m in log.messages([topic])
        ]


def best_pass_ms(step: Callable[[], object], scans: int, repeat: int) -> float:
    """Best of `repeat` runs of `step` (one pass over all scans), per scan in ms."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        step()
        best = min(best, time.perf_counter() - t0)
    return best / scans * 1e3


def bench(path: Path, topic: str, repeat: int) -> None:
    """Print per-scan decode_scan and packet_samples times for one topic."""
    msgs = read_scans(path, topic)
    if not msgs:
        print(f"{path.name} {topic}: no messages")
        return
    family = SCAN_TYPES.get(msgs[0].msgtype)
    if family is None or family == "ouster":
        raise SystemExit(f"error: {topic}: {msgs[0].msgtype} is not a scan-message packet type")
    chunks: list[PacketChunk] = []
    for i, msg in enumerate(msgs):
        chunk = decode_scan(family, msg, i)
        if chunk is not None:
            chunks.append(chunk)
    if not chunks:
        print(f"{path.name} {topic}: no packets")
        return
    packets = sum(c.timing.n_packets for c in chunks) / len(chunks)

    def decode_all() -> None:
        for i, msg in enumerate(msgs):
            decode_scan(family, msg, i)

    def samples_all() -> None:
        for c in chunks:
            packet_samples(c.timing, c.driver_stamp_ns)

    dec = best_pass_ms(decode_all, len(msgs), repeat)
    smp = best_pass_ms(samples_all, len(chunks), repeat)
    print(
        f"{path.name} {topic}: {len(chunks)} scans of {packets:.0f} packets "
        f"({chunks[0].timing.model}); per scan: decode_scan {dec:.3f} ms, "
        f"packet_samples {smp:.3f} ms, total {dec + smp:.3f} ms"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log_topic", nargs="*", help="pairs of LOG TOPIC")
    parser.add_argument("--repeat", type=int, default=20)
    args = parser.parse_args()
    pairs = args.log_topic
    if not pairs:
        cached = sorted((HERE / ".cache").glob(DEFAULT_LOGS))
        if not cached:
            parser.error(
                "no cached bench log: run `python benchmarks/bench_audit.py --quick` first, "
                "or give LOG TOPIC"
            )
        pairs = [str(cached[-1]), DEFAULT_TOPIC]
    if len(pairs) % 2:
        parser.error("give LOG TOPIC pairs")
    for path, topic in zip(pairs[::2], pairs[1::2], strict=True):
        try:
            bench(Path(path), topic, args.repeat)
        except SyncauditError as exc:
            raise SystemExit(f"error: {exc}") from None


if __name__ == "__main__":
    main()
