#!/usr/bin/env python
"""Benchmark of `syncaudit audit` on a cloud-only log of a 128-beam LiDAR (issue 26).

1. Generates (once, cached in `--cache-dir`) a simulated drive of `--minutes` minutes: a
   VLS-128 at 600 rpm written only as `sensor_msgs/PointCloud2` on /points (the
   ros-drivers/velodyne layout, 32 points per block: ~240k points per cloud), three
   cameras with exposure metadata and trigger records, its rig and truth.
2. Warms the page cache, then runs in `--repeat` interleaved rounds, each as a subprocess:
   the audit (`syncaudit audit LOG --rig RIG --json`) and its floor (the container's
   library, `mcap.reader.make_reader(f).iter_messages(topics=...)`, reading the same
   topics and doing nothing per message). Each figure is the median-wall run.
3. Prints wall and CPU seconds of both, their ratio, and the points per second audited.

The issue's size is 10 minutes (~32 GB of clouds); on a shared 2-core machine run a
shorter log (`--minutes 0.5`) and read the per-cloud cost, which is what scales.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
FLOOR_CODE = (
    "import sys\n"
    "from mcap.reader import make_reader\n"
    "with open(sys.argv[1], 'rb') as f:\n"
    "    for _ in make_reader(f).iter_messages(topics=sys.argv[2:]):\n"
    "        pass\n"
)


def generate(cache: Path, minutes: float) -> tuple[Path, Path, dict[str, object]]:
    """The cached log, its rig (LiDAR topic /points) and its truth."""
    from syncaudit.simulate.rig_file import rig_from_truth
    from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log

    cache.mkdir(parents=True, exist_ok=True)
    log = cache / f"clouds_vls128_{minutes:g}min.mcap"
    rig = log.with_suffix(".rig.json")
    truth_file = Path(str(log) + ".truth.json")
    if not (log.exists() and rig.exists() and truth_file.exists()):
        config = SyncSimConfig(
            duration_s=minutes * 60.0,
            lidar_model="VLS-128",
            cloud_convention="velodyne",
            cloud_beams=32,
            lidar_packets=False,
            lidar_returns="random",
            overwrite=True,
        )
        truth = simulate_sync_log(log, config)
        model = rig_from_truth(truth)
        model = model.model_copy(
            update={"lidar": model.lidar.model_copy(update={"topic": "/points"})}
        )
        rig.write_text(json.dumps(model.model_dump(mode="json")))
    return log, rig, json.loads(truth_file.read_text())


def run(argv: list[str]) -> tuple[float, float]:
    """Wall and CPU (user + sys of the child and its reaped children) seconds of a command."""
    start = time.perf_counter()
    process = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - start
    if os.waitstatus_to_exitcode(status) not in (0, 1):
        error = process.stderr.read().decode() if process.stderr else ""
        raise SystemExit(f"{argv[:3]} failed: {error.strip().splitlines()[-1:]}")
    return wall, usage.ru_utime + usage.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--jobs", type=int, default=None, help="audit worker processes")
    parser.add_argument("--cache-dir", type=Path, default=REPO / "benchmarks" / ".cache")
    args = parser.parse_args()
    log, rig, truth = generate(args.cache_dir, args.minutes)
    cameras = truth["cameras"]
    assert isinstance(cameras, dict)
    topics = ["/points", *{t for cam in cameras.values() for t in cam["topics"].values()}]
    with log.open("rb") as f:  # warm the page cache
        while f.read(1 << 24):
            pass
    audit = [sys.executable, "-m", "syncaudit", "audit", str(log), "--rig", str(rig), "--json"]
    if args.jobs:
        audit += ["--jobs", str(args.jobs)]
    floor = [sys.executable, "-c", FLOOR_CODE, str(log), *topics]
    runs: dict[str, list[tuple[float, float]]] = {"audit": [], "floor": []}
    for _ in range(args.repeat):
        runs["audit"].append(run(audit))
        runs["floor"].append(run(floor))
    lidar = truth["lidar"]
    assert isinstance(lidar, dict)
    clouds = int(lidar["scans"])
    points = int(lidar["packets_written"]) * 12 * 32  # 12 blocks a packet, 32 points a block
    size_gb = log.stat().st_size / 1e9
    print(
        f"log: {log.name}, {size_gb:.2f} GB, {clouds} clouds, ~{points / clouds:,.0f} points each"
    )
    figures = {}
    for name, values in runs.items():
        wall, cpu = min(values, key=lambda v: abs(v[0] - statistics.median(w for w, _ in values)))
        figures[name] = wall
        print(f"{name:>6}: wall {wall:7.2f} s  CPU {cpu:7.2f} s")
    print(
        f"audit / floor: {figures['audit'] / figures['floor']:.2f}x; "
        f"{points / figures['audit'] / 1e6:.1f} M points/s, "
        f"{figures['audit'] / clouds * 1e3:.2f} ms per cloud"
    )


if __name__ == "__main__":
    main()
