#!/usr/bin/env python
"""Benchmark of method B (`syncaudit.calib.calibrate_log`) across the simulator's matrix.

For each case of `syncaudit.simulate.calib_session.MATRIX` (turntable; driving sessions
with 25-45 deg turns and 0.3-1.1 m moves between short stops, motion-distorted scans,
roof/bumper/diagonal mounts, 16/32/64/128 beams, organised clouds, two-level tf chains,
odometry) and seed it simulates a session (not timed; written to a temporary folder),
then times the whole calibration -- reading, stops, the vehicle's motion between stops,
cross-scan GICP, pose graphs, map-to-map GICP, validation -- and scores the calibrated
extrinsic against the simulator's truth. It also times the refusal of a ground-plus-one-
wall session and of a corridor (each must name the free direction). Then it prints the
table: per case, rotation and translation error (max, median), wall and CPU time (max,
median), against the targets (16 beams 0.3 deg / 2 cm, 32 and 64 beams 0.1 deg / 1 cm,
128 beams 0.05 deg / 0.5 cm; < 30 s per session; a refusal < 10 s), and the load average
at the start, per session and at the end. Every figure is measured in that run; CPU time
is printed because on a shared machine wall time also measures the other users.

    python benchmarks/bench_calib.py                       # every case, seeds 0-9
    python benchmarks/bench_calib.py --cases drive-64-bumper --seeds 3
    python benchmarks/bench_calib.py --jobs 2               # two sessions at once
    python benchmarks/bench_calib.py --log-dir D --simulate-only   # write the sessions once
    python benchmarks/bench_calib.py --log-dir D                   # then time on them

Needs the `calib` extra (`pip install -e '.[calib]'`).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import platform
import re
import resource
import statistics
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any, Literal

import numpy as np

from syncaudit.calib import CalibConfig, calibrate_log, se3
from syncaudit.simulate.calib_config import calib_scene_config
from syncaudit.simulate.calib_session import (
    MATRIX,
    matrix_tolerance,
    simulate_calib_session,
    truth_path,
)

TARGET_S = 30.0
REFUSAL_TARGET_S = 10.0


def _cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _session(root: Path, case: str, seed: int, stops: int, *, keep: bool) -> dict[str, Any]:
    """Simulate one session (not timed) and return its truth; with `keep`, a session left
    in `root` by an earlier run with the same configuration is reused."""
    path = root / f"{case}_s{seed}_{stops}stops.mcap"
    config = calib_scene_config(seed=seed, **{"n_stops": stops, **MATRIX[case]})
    if keep and path.exists() and truth_path(path).exists():
        truth: dict[str, Any] = json.loads(truth_path(path).read_text())
        if truth["config"] == json.loads(json.dumps(config.model_dump(mode="json"))):
            return truth
    return simulate_calib_session(path, config)


def _run(root: Path, case: str, seed: int, stops: int, *, keep: bool) -> dict[str, Any]:
    path = root / f"{case}_s{seed}_{stops}stops.mcap"
    truth = _session(root, case, seed, stops, keep=keep)
    wall0, cpu0 = time.perf_counter(), _cpu_s()
    result = calibrate_log(path, CalibConfig())
    wall, cpu = time.perf_counter() - wall0, _cpu_s() - cpu0
    row: dict[str, Any] = {
        "case": case,
        "seed": seed,
        "wall_s": wall,
        "cpu_s": cpu,
        "calibratable": result.calibratable,
        "reason": result.reason,
        "stops_used": [sum(s.used for s in lidar.stops) for lidar in result.lidars],
        "moving_used": [
            0 if lidar.moving_scans is None else lidar.moving_scans.used for lidar in result.lidars
        ],
        "cross_check": [n for n in result.notes if n.startswith("cross-LiDAR check")],
        "rot_deg": None,
        "trans_cm": None,
    }
    rear = next(x for x in truth["lidars"] if x["topic"] == result.extrinsics[0].topic)
    true = np.array(rear[f"true_{truth['reference_lidar']}_from_lidar"]["matrix"])
    joint = result.joint.lidars[0].extrinsic if result.joint and result.joint.lidars else None
    for key, ext in (
        ("", result.extrinsics[0]),
        ("base_", result.baseline[0] if result.baseline else None),
        ("joint_", joint),
    ):
        row[f"{key}rot_deg"] = row[f"{key}trans_cm"] = None
        if ext is not None and ext.result is not None:
            rot_deg, trans_m = se3.transform_difference(true, np.array(ext.result.matrix))
            row[f"{key}rot_deg"], row[f"{key}trans_cm"] = rot_deg, trans_m * 100.0
    selection = result.joint.selection if result.joint is not None else []
    row["method"] = selection[0].method if selection else "baseline"
    row["why"] = selection[0].criterion if selection else "no joint estimate"
    costs = [selection[0].joint_map_cost_m2, selection[0].baseline_map_cost_m2] if selection else []
    row["cost_ratio"] = costs[1] / costs[0] if len(costs) == 2 and None not in costs else None
    lidar_out = result.joint.lidars[0] if result.joint and result.joint.lidars else None
    row["joint_sigma"] = None if lidar_out is None else (lidar_out.sigma_deg, lidar_out.sigma_cm)
    up = result.joint.up if result.joint is not None else None
    row["up"] = up.source if up is not None else None
    if not keep:
        for extra in path.parent.glob(path.name + "*"):
            extra.unlink()
    return row


def _refusal(
    root: Path, scene: Literal["ground_and_wall", "corridor"]
) -> tuple[float, float, str, bool]:
    """Wall and CPU seconds of refusing a degenerate 12-stop session, its reason, and
    whether the result names the free direction (structured `degeneracy`)."""
    path = root / f"{scene}.mcap"
    simulate_calib_session(path, calib_scene_config(motion="drive", scene=scene, n_stops=12))
    wall0, cpu0 = time.perf_counter(), _cpu_s()
    result = calibrate_log(path, CalibConfig())
    wall, cpu = time.perf_counter() - wall0, _cpu_s() - cpu0
    named = result.degeneracy is not None and result.degeneracy.kind == "translation"
    return wall, cpu, result.reason or "(not refused)", named


def _load() -> str:
    one, five, fifteen = os.getloadavg()
    return f"{one:.1f} {five:.1f} {fifteen:.1f}"


def _table(rows: list[dict[str, Any]], cases: list[str]) -> bool:
    """Print the per-case table; True when every case met its targets."""
    ok = True
    print(
        f"{'case':24s} {'n':>3s} {'rot max':>8s} {'rot med':>8s} {'cm max':>7s} {'cm med':>7s} "
        f"{'wall max':>8s} {'wall med':>8s} {'cpu max':>7s} {'cpu med':>7s} "
        f"{'base rot':>8s} {'base cm':>7s} {'jnt rot':>8s} {'jnt cm':>7s} {'worse':>5s} "
        f"{'chosen':>10s} {'moving':>6s}  target  verdict"
    )
    for case in cases:
        mine = [r for r in rows if r["case"] == case]
        done = [r for r in mine if r["rot_deg"] is not None]
        lim_rot, lim_cm = matrix_tolerance(MATRIX[case]["beams"])
        rot = [r["rot_deg"] for r in done] or [float("nan")]
        cm = [r["trans_cm"] for r in done] or [float("nan")]
        walls = [r["wall_s"] for r in mine]
        cpus = [r["cpu_s"] for r in mine]
        base = [r for r in mine if r.get("base_rot_deg") is not None]
        base_rot = max((r["base_rot_deg"] for r in base), default=float("nan"))
        base_cm = max((r["base_trans_cm"] for r in base), default=float("nan"))
        worse = sum(1 for r in mine if _worse_than_baseline(r))
        joint = [r for r in mine if r.get("joint_rot_deg") is not None]
        joint_rot = max((r["joint_rot_deg"] for r in joint), default=float("nan"))
        joint_cm = max((r["joint_trans_cm"] for r in joint), default=float("nan"))
        picked = [r.get("method") for r in mine]
        chosen = f"J{picked.count('joint')}/B{picked.count('baseline')}" + (
            f"/N{picked.count('none')}" if "none" in picked else ""
        )
        moving = sum(sum(r.get("moving_used") or []) for r in mine)
        good = (
            len(done) == len(mine)
            and max(rot) <= lim_rot
            and max(cm) <= lim_cm
            and max(cpus) < TARGET_S
            and worse == 0
        )
        ok &= good
        print(
            f"{case:24s} {len(mine):3d} {max(rot):8.4f} {statistics.median(rot):8.4f} "
            f"{max(cm):7.3f} {statistics.median(cm):7.3f} {max(walls):8.1f} "
            f"{statistics.median(walls):8.1f} {max(cpus):7.1f} {statistics.median(cpus):7.1f} "
            f"{base_rot:8.4f} {base_cm:7.3f} {joint_rot:8.4f} {joint_cm:7.3f} {worse:5d} "
            f"{chosen:>10s} {moving:6d}  "
            f"{lim_rot}/{lim_cm}  {'OK' if good else 'MISSED'}"
            + ("" if len(done) == len(mine) else f" ({len(mine) - len(done)} not calibrated)")
        )
    return ok


def _worse_than_baseline(row: dict[str, Any]) -> bool:
    """Whether the chosen estimate is farther from the truth than the baseline's, in
    rotation or translation, or missing where the baseline calibrated within the case's
    target (a refusal in place of a baseline outside it loses nothing a user could use)."""
    if row.get("base_rot_deg") is None:
        return False
    if row["rot_deg"] is None:
        lim_rot, lim_cm = matrix_tolerance(MATRIX[row["case"]]["beams"])
        return bool(row["base_rot_deg"] <= lim_rot and row["base_trans_cm"] <= lim_cm)
    return bool(
        row["rot_deg"] > row["base_rot_deg"] + 1e-4 or row["trans_cm"] > row["base_trans_cm"] + 1e-3
    )


_ROW = re.compile(
    r"^(?P<case>\S+) seed (?P<seed>\d+): wall +(?P<wall>[\d.]+) s, cpu +(?P<cpu>[\d.]+) s; "
    r"(?:(?P<rot>[\d.]+) deg (?P<cm>[\d.]+) cm|not calibrated: (?P<reason>.*?)); stops used"
    r"(?:.*?; baseline (?:(?P<brot>[\d.]+) deg (?P<bcm>[\d.]+) cm|not calibrated))?"
)


def _rows_from(paths: list[Path]) -> list[dict[str, Any]]:
    """The per-session lines of earlier runs' output (a matrix run in parts)."""
    rows = []
    for path in paths:
        for line in path.read_text().splitlines():
            m = _ROW.match(line)
            if m is None:
                continue
            rows.append(
                {
                    "case": m["case"],
                    "seed": int(m["seed"]),
                    "wall_s": float(m["wall"]),
                    "cpu_s": float(m["cpu"]),
                    "rot_deg": None if m["rot"] is None else float(m["rot"]),
                    "trans_cm": None if m["cm"] is None else float(m["cm"]),
                    "reason": m["reason"],
                    "base_rot_deg": None if m["brot"] is None else float(m["brot"]),
                    "base_trans_cm": None if m["bcm"] is None else float(m["bcm"]),
                }
            )
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    parser.add_argument("--cases", nargs="+", default=list(MATRIX), choices=list(MATRIX))
    parser.add_argument("--seeds", type=int, default=10, help="N seeds per case")
    parser.add_argument(
        "--first-seed", type=int, default=0, help="the seeds are K..K+N-1 (run a matrix in parts)"
    )
    parser.add_argument("--stops", type=int, default=12)
    parser.add_argument(
        "--log-dir",
        type=Path,
        help="keep the simulated sessions here and reuse them in later runs (default: a "
        "temporary folder, removed)",
    )
    parser.add_argument(
        "--skip-refusals",
        action="store_true",
        help="leave out the corridor and ground-plus-wall refusals (a part of a split run)",
    )
    parser.add_argument(
        "--simulate-only",
        action="store_true",
        help="only write the sessions into --log-dir (no calibration, no table)",
    )
    parser.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="sessions calibrated at once (each in its own process); above 1 the sessions "
        "share the cores, so wall seconds grow; CPU seconds stay each session's own",
    )
    parser.add_argument(
        "--table-from",
        type=Path,
        nargs="+",
        help="print the table of the sessions listed in earlier runs' output (no new run)",
    )
    args = parser.parse_args(argv)
    if args.table_from:
        rows_read = _rows_from(args.table_from)
        seen = sorted({r["seed"] for r in rows_read})
        print(f"{len(rows_read)} sessions (seeds {seen}) from {len(args.table_from)} run(s)")
        cases = [c for c in args.cases if any(r["case"] == c for r in rows_read)]
        return 0 if _table(rows_read, cases) else 1
    print(
        f"python {platform.python_version()}, {os.cpu_count()} cores, {platform.machine()}, "
        f"load average {_load()} (1/5/15 min); {args.stops} stops, two LiDARs, "
        f"1 cm range noise; {args.jobs} session(s) at once",
        flush=True,
    )
    rows = []
    if args.simulate_only and args.log_dir is None:
        parser.error("--simulate-only needs --log-dir")
    with tempfile.TemporaryDirectory(prefix="bench_calib_") as tmp:
        root = args.log_dir or Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        keep = args.log_dir is not None
        # Seeds outer, cases inner: an interrupted run still covers every case.
        seeds = range(args.first_seed, args.first_seed + args.seeds)
        runs = [(case, seed) for seed in seeds for case in args.cases]
        context = multiprocessing.get_context("spawn")  # small_gicp's OpenMP must not fork
        with ProcessPoolExecutor(max_workers=args.jobs, mp_context=context) as pool:
            if args.simulate_only:
                sims = [pool.submit(_session, root, c, s, args.stops, keep=True) for c, s in runs]
                for sim in sims:
                    sim.result()
                print(f"{len(runs)} sessions in {root}")
                return 0
            futures = [
                pool.submit(_run, root, case, seed, args.stops, keep=keep) for case, seed in runs
            ]
            for (case, seed), future in zip(runs, futures, strict=True):
                row = future.result()
                rows.append(row)
                err = (
                    f"{row['rot_deg']:.4f} deg {row['trans_cm']:.3f} cm"
                    if row["rot_deg"] is not None
                    else f"not calibrated: {row['reason']}"
                )
                base = (
                    f"{row['base_rot_deg']:.4f} deg {row['base_trans_cm']:.3f} cm"
                    if row["base_rot_deg"] is not None
                    else "not calibrated"
                )
                sigma = (
                    "none"
                    if row["joint_sigma"] is None
                    else f"{row['joint_sigma'][0]:.4f} deg {row['joint_sigma'][1]:.3f} cm"
                )
                print(
                    f"{case} seed {seed}: wall {row['wall_s']:5.1f} s, cpu {row['cpu_s']:5.1f} s;"
                    f" {err}; stops used {row['stops_used']};"
                    f" moving scans used {row.get('moving_used')}; load {os.getloadavg()[0]:.1f};"
                    f" {row['method']} ({row['why']}; baseline/joint map cost"
                    f" {row['cost_ratio'] if row['cost_ratio'] is None else round(row['cost_ratio'], 5)};"
                    f" up from {row['up']}); joint 1-sigma {sigma}; baseline {base}",
                    flush=True,
                )
                for note in row["cross_check"]:
                    print(f"    {note}", flush=True)
        refusals = (
            {}
            if args.skip_refusals
            else {
                "ground_and_wall": _refusal(Path(tmp), "ground_and_wall"),
                "corridor": _refusal(Path(tmp), "corridor"),
            }
        )
    print()
    ok = _table(rows, args.cases)
    for scene, (wall, cpu, reason, named) in refusals.items():
        good = cpu < REFUSAL_TARGET_S and "degenerate scene" in reason and named
        ok &= good
        print(
            f"{scene} refused in wall {wall:.1f} s, cpu {cpu:.1f} s "
            f"(target < {REFUSAL_TARGET_S:.0f} s): {'OK' if good else 'MISSED'}: {reason}"
        )
    print(f"load average at the end {_load()} (1/5/15 min) on {os.cpu_count()} cores")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
