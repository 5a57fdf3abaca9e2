#!/usr/bin/env python
"""Benchmark of `syncaudit gate` over many logs (issue 14); prints its figures.

1. Generates (once, cached under `--cache-dir`) `--small` sample-sized logs (10 s, VLP-16,
   three cameras, like sample_logs/vlp16_three_cameras.mcap, one seed each) and
   `--large` big ones (VLS-128 and six JPEG-sized cameras, the `bench_audit.py` log) of
   at least `--large-gb` each, every log with its rig file beside it.
2. Baseline read + decode + analysis of each small log: `audit_log(jobs=1)` in one warm
   process (no interpreter start-up), i.e. what a log costs on its own.
3. `syncaudit gate` as a subprocess (wall time; peak RSS of the largest process in its
   tree from `os.wait4`): on the small logs with one worker, on half of them with one
   worker (the marginal cost per log = difference / difference in logs, start-up
   cancels), and with one worker per core (logs/min, GB/min); then on the large logs,
   against `syncaudit audit` of each large log in turn (GB/min of the single-log audit).
4. Prints the per-log overhead beyond the baseline (target < 50 ms), throughput, the
   large-log GB/min ratio (target within 10 %) and the driver's memory for N/2 vs N logs
   (target: flat).

Full run (issue 14): `python benchmarks/bench_gate.py` (300 small, 10 large of 1 GB).
Reduced: `python benchmarks/bench_gate.py --small 60 --large 2 --large-gb 0.3`.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "benchmarks"))
DEFAULT_CACHE = REPO / "benchmarks" / ".cache" / "gate"
SMALL_DURATION_S = 10.0
CALIBRATION_S = 2.0
TARGET_OVERHEAD_MS = 50.0
TARGET_GB_RATIO = 1.10


def small_logs(cache: Path, count: int) -> list[Path]:
    """`count` sample-sized logs, generated once (several per simulate process)."""
    folder = cache / "small"
    folder.mkdir(parents=True, exist_ok=True)
    logs = [folder / f"drive_{seed:04d}.mcap" for seed in range(count)]
    missing = [p for p in logs if not p.with_name(p.name + ".rig.yaml").exists()]
    if missing:
        code = (
            "import sys, yaml\n"
            "from pathlib import Path\n"
            "from syncaudit.simulate.rig_file import rig_from_truth\n"
            "from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log\n"
            "for arg in sys.argv[1:]:\n"
            "    out = Path(arg); seed = int(out.stem.split('_')[1])\n"
            f"    cfg = SyncSimConfig(seed=seed, duration_s={SMALL_DURATION_S}, overwrite=True)\n"
            "    truth = simulate_sync_log(out, cfg)\n"
            "    rig = rig_from_truth(truth).model_dump(mode='json', exclude_defaults=True)\n"
            "    out.with_name(out.name + '.rig.yaml').write_text(yaml.safe_dump(rig, sort_keys=False))\n"
        )
        print(f"generating {len(missing)} small logs in {folder} ...", flush=True)
        half = (len(missing) + 1) // 2
        procs = [
            subprocess.Popen([sys.executable, "-c", code, *map(str, part)])
            for part in (missing[:half], missing[half:])
            if part
        ]
        for proc in procs:
            if proc.wait() != 0:
                raise SystemExit("generating the small logs failed")
    return logs


def large_logs(cache: Path, count: int, size_gb: float) -> list[Path]:
    """`count` big logs of at least `size_gb` (the bench_audit rig; seeds differ by name)."""
    import bench_audit

    folder = cache / "large"
    folder.mkdir(parents=True, exist_ok=True)
    rate_file = folder / "bytes_per_s.json"
    if not rate_file.exists():
        probe = folder / "probe.mcap"
        bench_audit.generate(probe, CALIBRATION_S)
        rate_file.write_text(json.dumps(probe.stat().st_size / CALIBRATION_S))
        probe.unlink()
        probe.with_name(probe.name + ".rig.yaml").unlink(missing_ok=True)
        Path(str(probe) + ".truth.json").unlink(missing_ok=True)
    rate = json.loads(rate_file.read_text())
    duration = size_gb * 1e9 / rate * 1.02
    logs = []
    for index in range(count):
        out = folder / f"big_{size_gb:g}gb_{index}.mcap"
        if not out.with_name(out.name + ".rig.yaml").exists():
            print(f"generating {out.name} ({duration:.0f} s of log) ...", flush=True)
            _generate_large(out, duration, bench_audit.SEED + index)
        logs.append(out)
    return logs


def _generate_large(out: Path, duration_s: float, seed: int) -> None:
    """The bench_audit log (VLS-128, six cameras) with its own seed, and its rig file."""
    import bench_audit
    import yaml

    from syncaudit.simulate.rig_file import rig_from_truth
    from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log

    config = {**bench_audit.sim_config(duration_s), "seed": seed}
    truth = simulate_sync_log(out, SyncSimConfig.model_validate(config))
    rig = rig_from_truth(truth).model_dump(mode="json", exclude_defaults=True)
    out.with_name(out.name + ".rig.yaml").write_text(yaml.safe_dump(rig, sort_keys=False))


def run_measured(argv: list[str], env: dict[str, str] | None = None) -> tuple[float, float, int]:
    """(wall s, peak RSS MB of the largest process in the tree, exit code) of a subprocess."""
    start = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    stderr = proc.stderr.read().decode() if proc.stderr else ""
    code = os.waitstatus_to_exitcode(status)
    if code not in (0, 10):
        raise SystemExit(f"{' '.join(argv[:4])} ... exited {code}: {stderr[-500:]}")
    return wall, usage.ru_maxrss / 1024, code


def gate(
    paths: list[Path], policy: Path, jobs: int, scratch: Path, *, db: bool
) -> tuple[float, float, float]:
    """(wall s, peak RSS MB, sum of the workers' per-log audit times s; 0 without a DB)."""
    manifest = scratch / f"manifest_{len(paths)}_{jobs}_{db}.jsonl"
    manifest.write_text("".join(json.dumps({"path": str(p)}) + "\n" for p in paths))
    argv = [
        sys.executable,
        "-m",
        "syncaudit.cli",
        "gate",
        str(manifest),
        "--policy",
        str(policy),
        "--jobs",
        str(jobs),
    ]
    db_path = scratch / f"fleet_{time.monotonic_ns()}.duckdb"
    argv += ["--db", str(db_path)] if db else ["--no-db"]
    wall, rss, _ = run_measured(argv)
    audit_s = 0.0
    if db:
        import duckdb

        with duckdb.connect(str(db_path), read_only=True) as con:
            row = con.execute("SELECT sum(elapsed_s), count(*) FROM logs").fetchone()
        assert row is not None and row[1] == len(paths), row
        audit_s = float(row[0])
    return wall, rss, audit_s


def baseline_s(paths: list[Path]) -> list[float]:
    """Audit time of each log (jobs=1) in this warm process: its read, decode and analysis."""
    from syncaudit.audit.run import audit_log
    from syncaudit.rig import load_rig

    audit_log(paths[0], load_rig(str(paths[0]) + ".rig.yaml"), jobs=1)  # warm imports
    times = []
    for path in paths:
        start = time.perf_counter()
        audit_log(path, load_rig(str(path) + ".rig.yaml"), jobs=1)
        times.append(time.perf_counter() - start)
    return times


def warm_audit_s(paths: list[Path], jobs: int) -> float:
    """Wall time of `audit_log(jobs=jobs)` of each log in turn in this (warm) process."""
    from syncaudit.audit.run import audit_log
    from syncaudit.rig import load_rig

    start = time.perf_counter()
    for path in paths:
        audit_log(path, load_rig(str(path) + ".rig.yaml"), jobs=jobs)
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--small", type=int, default=300)
    parser.add_argument("--large", type=int, default=10)
    parser.add_argument("--large-gb", type=float, default=1.0)
    parser.add_argument("--cache-dir", type=Path, default=DEFAULT_CACHE)
    parser.add_argument("--rounds", type=int, default=3, help="Interleaved rounds (median).")
    args = parser.parse_args(argv)
    cores = len(os.sched_getaffinity(0))
    small = small_logs(args.cache_dir, args.small)
    large = large_logs(args.cache_dir, args.large, args.large_gb) if args.large else []
    small_gb = sum(p.stat().st_size for p in small) / 1e9
    load_start = os.getloadavg()  # after generating: what the measurements start in
    with tempfile.TemporaryDirectory(prefix="bench_gate_") as tmp:
        scratch = Path(tmp)
        policy = scratch / "policy.yaml"
        policy.write_text(
            "defaults: {camera: {error_mean_us: {max: 1000000}, error_var_us2: {max: 1.0e+12}}}\n"
        )
        base = baseline_s(small)
        mean_base_ms = 1e3 * sum(base) / len(base)
        half = small[: len(small) // 2]
        added = len(small) - len(half)
        rounds = []
        for _ in range(args.rounds):  # interleaved: load from other work hits both sizes
            wall_half, rss_half, audit_half = gate(half, policy, 1, scratch, db=True)
            wall_all, rss_all, audit_all = gate(small, policy, 1, scratch, db=True)
            # Outside-the-audit time per added log, wall and audit times from the same runs.
            overhead = ((wall_all - audit_all) - (wall_half - audit_half)) / added
            rounds.append((overhead, wall_half, wall_all, audit_half, audit_all))
        rounds.sort()
        overhead_s, wall_half, wall_all, audit_half, audit_all = rounds[len(rounds) // 2]
        overhead_ms = 1e3 * overhead_s
        marginal_ms = 1e3 * (wall_all - wall_half) / added
        in_worker_ms = 1e3 * (audit_all - audit_half) / added
        spread = ", ".join(f"{1e3 * r[0]:+.1f}" for r in rounds)
        wall_par, _, _ = gate(small, policy, cores, scratch, db=False)
        wall_db, rss_db, _ = gate(small, policy, cores, scratch, db=True)
        print(
            f"machine: {cores} cores (shared with other work: figures are indicative); load "
            f"average at the start: {' '.join(f'{x:.2f}' for x in load_start)}"
        )
        print(f"small logs: {len(small)} x {1e3 * small_gb / len(small):.2f} MB")
        print(f"  baseline audit (read+decode+analysis, warm, jobs=1): {mean_base_ms:.1f} ms/log")
        print(
            f"  gate, 1 worker, database on: {len(half)} logs {wall_half:.2f} s, {len(small)} logs "
            f"{wall_all:.2f} s -> marginal {marginal_ms:.1f} ms/log, of which the audit in the "
            f"worker {in_worker_ms:.1f} ms: overhead {overhead_ms:+.1f} ms/log "
            f"(target < {TARGET_OVERHEAD_MS:.0f}); vs the warm baseline "
            f"{marginal_ms - mean_base_ms:+.1f} ms/log; overhead of each round: {spread} ms"
        )
        print(
            f"  gate, {cores} workers: {wall_par:.2f} s = {60 * len(small) / wall_par:.0f} logs/min, "
            f"{60 * small_gb / wall_par:.2f} GB/min; with the database {wall_db:.2f} s "
            f"({60 * len(small) / wall_db:.0f} logs/min)"
        )
        print(
            f"  peak RSS of the largest process (database on): {rss_half:.0f} MB ({len(half)} "
            f"logs) vs {rss_all:.0f} MB ({len(small)} logs); {rss_db:.0f} MB with {cores} workers"
        )
        if large:
            large_gb = sum(p.stat().st_size for p in large) / 1e9
            audit_walls = []
            for path in large:
                wall, _, _ = run_measured(
                    [
                        sys.executable,
                        "-m",
                        "syncaudit.cli",
                        "audit",
                        str(path),
                        "--rig",
                        str(path) + ".rig.yaml",
                        "--jobs",
                        str(cores),
                    ]
                )
                audit_walls.append(wall)
            warm_s = warm_audit_s(large, cores)
            wall_large, rss_large, _ = gate(large, policy, cores, scratch, db=True)
            single = 60 * large_gb / sum(audit_walls)
            warm = 60 * large_gb / warm_s
            ganged = 60 * large_gb / wall_large
            print(f"large logs: {len(large)} x {large_gb / len(large):.2f} GB")
            print(
                f"  single-log audit (`syncaudit audit --jobs {cores}`), one after another: "
                f"{sum(audit_walls):.2f} s = {single:.2f} GB/min"
            )
            print(
                f"  the same audits in one warm process (audit_log, jobs={cores}; no start-up): "
                f"{warm_s:.2f} s = {warm:.2f} GB/min"
            )
            print(
                f"  gate ({cores} workers, database on): {wall_large:.2f} s = {ganged:.2f} GB/min, "
                f"{ganged / single:.2f}x the single-log audit's, {ganged / warm:.2f}x the warm "
                f"audit's (target >= {1 / TARGET_GB_RATIO:.2f}); peak RSS {rss_large:.0f} MB"
            )
        print(f"load average after the run: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
