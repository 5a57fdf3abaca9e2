#!/usr/bin/env python
"""Benchmark of method B (`syncaudit.calib.calibrate_log`) on simulated turntable sessions.

For each beam count and seed it simulates a session (not timed; written to a temporary
folder), then times the whole calibration -- reading the log, finding stops, the turn
chain, cross-scan GICP, pose graphs, map-to-map GICP, validation -- and scores the
calibrated extrinsic against the simulator's truth. It prints one row per run, then the
figures the issue asks for: the wall time of a 12-stop calibration against the 30 s
target, and the worst error per beam count against 0.1 deg / 1 cm (32 beams) and
0.05 deg / 0.5 cm (128 beams). Every figure is measured in that run.

    python benchmarks/bench_calib.py                    # 32 and 128 beams, seeds 0-4
    python benchmarks/bench_calib.py --beams 128 --seeds 10 --stops 12

Needs the `calib` extra (`pip install -e '.[calib]'`).
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from syncaudit.calib import CalibConfig, calibrate_log, se3
from syncaudit.calib.config import CalibSceneConfig, rig_preset
from syncaudit.simulate.calib_session import simulate_calib_session

TARGET_S = 30.0
LIMITS = {32: (0.1, 1.0), 128: (0.05, 0.5)}
"""Accuracy targets per beam count: (rotation deg, translation cm)."""


def _cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _run(root: Path, beams: int, seed: int, stops: int) -> dict[str, Any]:
    path = root / f"calib_b{beams}_s{seed}.mcap"
    truth = simulate_calib_session(
        path, CalibSceneConfig(seed=seed, n_stops=stops, lidars=rig_preset(beams))
    )
    wall0, cpu0 = time.perf_counter(), _cpu_s()
    result = calibrate_log(path, CalibConfig())
    wall, cpu = time.perf_counter() - wall0, _cpu_s() - cpu0
    row: dict[str, Any] = {
        "beams": beams,
        "seed": seed,
        "wall_s": wall,
        "cpu_s": cpu,
        "calibratable": result.calibratable,
        "passed": result.passed,
        "stops_used": [sum(s.used for s in lidar.stops) for lidar in result.lidars],
        "stages": result.timings_s,
        "rot_deg": None,
        "trans_cm": None,
    }
    ext = result.extrinsics[0]
    if ext.result is not None:
        rear = next(x for x in truth["lidars"] if x["topic"] == ext.topic)
        true = np.array(rear[f"true_{truth['reference_lidar']}_from_lidar"]["matrix"])
        rot_deg, trans_m = se3.transform_difference(true, np.array(ext.result.matrix))
        row["rot_deg"], row["trans_cm"] = rot_deg, trans_m * 100.0
    for extra in path.parent.glob(path.name + "*"):
        extra.unlink()
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--beams", type=int, nargs="+", default=[32, 128])
    parser.add_argument("--seeds", type=int, default=5, help="seeds 0..N-1 per beam count")
    parser.add_argument("--stops", type=int, default=12)
    args = parser.parse_args(argv)
    print(
        f"python {platform.python_version()}, {os.cpu_count()} cores, {platform.machine()}; "
        f"{args.stops} stops, two LiDARs (front/rear, 120 deg views), 1 cm range noise"
    )
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_calib_") as tmp:
        for beams in args.beams:
            for seed in range(args.seeds):
                row = _run(Path(tmp), beams, seed, args.stops)
                rows.append(row)
                err = (
                    f"{row['rot_deg']:.4f} deg {row['trans_cm']:.3f} cm"
                    if row["rot_deg"] is not None
                    else "not calibrated"
                )
                stages = ", ".join(f"{k} {v:.1f}" for k, v in row["stages"].items() if k != "total")
                print(
                    f"beams {beams:3d} seed {seed}: wall {row['wall_s']:5.1f} s, cpu "
                    f"{row['cpu_s']:5.1f} s; error {err}; stops used {row['stops_used']}; "
                    f"[{stages}]",
                    flush=True,
                )
    ok = True
    print()
    for beams in args.beams:
        mine = [r for r in rows if r["beams"] == beams]
        walls = [r["wall_s"] for r in mine]
        verdict = "OK" if max(walls) < TARGET_S else "OVER"
        ok &= verdict == "OK"
        print(
            f"{beams}-beam {args.stops}-stop calibration wall time: median "
            f"{statistics.median(walls):.1f} s, max {max(walls):.1f} s "
            f"(target < {TARGET_S:.0f} s): {verdict}"
        )
        calibrated = [r for r in mine if r["rot_deg"] is not None]
        if beams in LIMITS and calibrated:
            lim_rot, lim_cm = LIMITS[beams]
            worst_rot = max(r["rot_deg"] for r in calibrated)
            worst_cm = max(r["trans_cm"] for r in calibrated)
            good = len(calibrated) == len(mine) and worst_rot <= lim_rot and worst_cm <= lim_cm
            ok &= good
            print(
                f"{beams}-beam worst error over {len(mine)} seeds: {worst_rot:.4f} deg, "
                f"{worst_cm:.3f} cm (target {lim_rot} deg, {lim_cm} cm; "
                f"{len(mine) - len(calibrated)} not calibrated): {'OK' if good else 'MISSED'}"
            )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
