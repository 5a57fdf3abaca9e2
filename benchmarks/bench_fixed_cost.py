#!/usr/bin/env python
"""Benchmark of syncaudit's fixed cost (issue 13): a sample-sized audit and `--help`.

What a user waits for on a small log is start-up, not reading: the interpreter, the
imports a command needs, opening the log, the analysis and the report. This runs, as
subprocesses of the installed console script, in `--runs` interleaved rounds after
syncaudit's bytecode is compiled (`compileall`: an environment with PYTHONDONTWRITEBYTECODE
set would otherwise compile every module from source on every run, ~0.07 CPU s that an
installed wheel never pays) and one unmeasured warm-up round (page cache warm):

- `python -c pass`: the interpreter alone, the floor under every command;
- `syncaudit --help` (target <= 0.2 s wall);
- `syncaudit audit LOG --rig LOG.rig.yaml` on the README's sample log (target <= 0.5 s
  wall), its tables to a pipe as in CI.

and prints, per command, the median, lowest and highest wall time, the median CPU time
(user + sys of the command and its worker processes, from getrusage), and the machine's
load average and the CPU the rest of the machine used meanwhile: a figure taken on a busy
machine says so. `--imports` adds where
the audit's import time goes (`python -X importtime`, cumulative, the heavy packages).

Run `python benchmarks/bench_fixed_cost.py --help`. Standard library only.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
SAMPLE_LOG = REPO / "sample_logs" / "vlp16_three_cameras.mcap"
"""The log of the README's first command."""
TARGET_AUDIT_S = 0.5
TARGET_HELP_S = 0.2
IMPORTS = (
    "typer",
    "syncaudit.cli",
    "numpy",
    "yaml",
    "pydantic",
    "mcap.reader",
    "zstandard",
    "rosbags.typesys",
    "rich",
    "pandas",
    "syncaudit.rig",
    "syncaudit.logs",
    "syncaudit.logs.parallel",
    "syncaudit.audit.run",
    "syncaudit.analysis.sync",
    "syncaudit.report.console",
)
"""Modules whose cumulative import time `--imports` prints (when the audit imports them)."""


@dataclass(slots=True)
class Contender:
    """One command and its measured runs."""

    name: str
    argv: list[str]
    env: dict[str, str] | None = None
    """Environment of the run (None: this one's)."""
    wall_s: list[float] = field(default_factory=list)
    cpu_s: list[float] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)


def _busy_s() -> float:
    """CPU seconds the whole machine has been busy since boot (from /proc/stat)."""
    try:
        with open("/proc/stat") as f:
            fields = [int(v) for v in f.readline().split()[1:]]
    except OSError:
        return float("nan")
    user, nice, system, _idle, _iowait, irq, softirq, steal = (fields + [0] * 8)[:8]
    return (user + nice + system + irq + softirq + steal) / os.sysconf("SC_CLK_TCK")


def _console_script() -> list[str]:
    """The venv's `syncaudit` script (what a user runs), else `python -m syncaudit`."""
    exe = Path(sys.executable).with_name("syncaudit")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "syncaudit"]


def run_once(contender: Contender, *, record: bool = True) -> None:
    """Run the command once with its output to pipes; record wall and CPU time."""
    start = time.perf_counter()
    proc = subprocess.Popen(
        contender.argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=REPO, env=contender.env
    )
    out, err = proc.communicate()
    wall = time.perf_counter() - start
    # communicate() reaped it; the children's rusage delta is its CPU time.
    if proc.returncode != 0:
        last = (err or out).decode(errors="replace").strip().splitlines()
        contender.failures.append(f"exit {proc.returncode}: {last[-1] if last else ''}")
    if record:
        contender.wall_s.append(wall)


def _children_cpu_s() -> float:
    """User + system CPU seconds of this process's reaped children (getrusage: microsecond
    resolution, where os.times() counts 10 ms clock ticks)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def measure(contenders: list[Contender], runs: int) -> tuple[float, float, float]:
    """`runs` interleaved rounds after one warm-up; (load before, load after, others' CPU s)."""
    for contender in contenders:
        run_once(contender, record=False)
    load_before = os.getloadavg()[0]
    others = 0.0
    for _ in range(runs):
        for contender in contenders:
            busy = _busy_s()
            before = _children_cpu_s()
            run_once(contender)
            cpu = _children_cpu_s() - before
            contender.cpu_s.append(cpu)
            others += max(0.0, _busy_s() - busy - cpu)
    return load_before, os.getloadavg()[0], others


def compile_bytecode(src_dirs: Sequence[Path]) -> str:
    """Compile the `syncaudit` packages of these source folders (or of the import path)."""
    where = [str(d / "syncaudit") for d in src_dirs]
    if not where:
        import importlib.util

        spec = importlib.util.find_spec("syncaudit")
        where = list(spec.submodule_search_locations or []) if spec is not None else []
    if not where:
        return "syncaudit not importable"
    done = subprocess.run([sys.executable, "-m", "compileall", "-q", *where], check=False)
    return "compiled" if done.returncode == 0 else f"compileall exit {done.returncode}"


def import_times(argv: Sequence[str]) -> dict[str, float]:
    """Cumulative import time (s) of each module in IMPORTS that `argv` imports."""
    env = dict(os.environ, PYTHONPROFILEIMPORTTIME="1")
    done = subprocess.run(argv, capture_output=True, text=True, env=env, cwd=REPO, check=False)
    found: dict[str, float] = {}
    pattern = re.compile(r"import time:\s+\d+\s+\|\s+(\d+)\s+\|\s*(\S+)")
    for line in done.stderr.splitlines():
        match = pattern.match(line)
        if match and match.group(2) in IMPORTS:
            found[match.group(2)] = int(match.group(1)) / 1e6
    return found


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description="Fixed cost of syncaudit: a sample-sized audit and --help (issue 13)."
    )
    parser.add_argument("--runs", type=int, default=10, help="measured rounds (default 10)")
    parser.add_argument("--log", type=Path, default=SAMPLE_LOG, help="the small log to audit")
    parser.add_argument(
        "--imports", action="store_true", help="also print the audit's import times"
    )
    parser.add_argument(
        "--baseline-src",
        type=Path,
        help="also run --help and the audit with syncaudit imported from this src folder "
        "(e.g. `git archive <commit> src | tar -x -C DIR`), interleaved: before/after",
    )
    return parser.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    log: Path = args.log.resolve()
    cli = _console_script()
    audit = Contender(
        "syncaudit audit (sample)", [*cli, "audit", str(log), "--rig", f"{log}.rig.yaml"]
    )
    contenders = [
        Contender("python -c pass", [sys.executable, "-c", "pass"]),
        Contender("syncaudit --help", [*cli, "--help"]),
        audit,
    ]
    if args.baseline_src is not None:
        src = str(args.baseline_src.resolve())
        env = dict(os.environ, PYTHONPATH=src)
        contenders += [Contender(f"{c.name} [baseline]", c.argv, env) for c in contenders[1:]]
        print(f"baseline: syncaudit from {src}")
    runs = max(1, args.runs)
    trees = [REPO / "src"] if (REPO / "src" / "syncaudit").is_dir() else []
    if args.baseline_src is not None:
        trees.append(args.baseline_src.resolve())
    print(f"syncaudit bytecode: {compile_bytecode(trees)}")
    load_before, load_after, others = measure(contenders, runs)
    print(
        f"syncaudit fixed cost: {runs} run(s) each, interleaved, after a warm-up; {os.cpu_count()} "
        f"cores; load average {load_before:.2f} before, {load_after:.2f} after (1 min); the rest "
        f"of the machine used {others:.1f} CPU s meanwhile"
    )
    print(f"log: {log.relative_to(REPO) if log.is_relative_to(REPO) else log}")
    head = f"{'command':<40}{'median s':>10}{'min s':>8}{'max s':>8}{'CPU s':>8}"
    print(head)
    print("-" * len(head))
    for c in contenders:
        if c.failures:
            print(f"{c.name:<40}  FAILED: {c.failures[0]}")
            continue
        print(
            f"{c.name:<40}{statistics.median(c.wall_s):>10.3f}{min(c.wall_s):>8.3f}"
            f"{max(c.wall_s):>8.3f}{statistics.median(c.cpu_s):>8.3f}"
        )
    print(
        "wall s of every run: "
        + "; ".join(f"{c.name}: " + " ".join(f"{w:.3f}" for w in c.wall_s) for c in contenders)
    )
    verdicts = (
        (contenders[1], TARGET_HELP_S, "syncaudit --help"),
        (audit, TARGET_AUDIT_S, "audit of the sample log"),
    )
    print("targets (median wall):")
    for c, target, what in verdicts:
        if c.failures:
            print(f"  [NOT MET] {what} <= {target} s: it failed")
            continue
        median = statistics.median(c.wall_s)
        mark = "met" if median <= target else "NOT MET"
        print(f"  [{mark}] {what} <= {target} s: {median:.3f} s")
    if args.imports:
        found = import_times([*audit.argv])
        print("cumulative import time in the audit (python -X importtime, one run):")
        for name in IMPORTS:
            if name in found:
                print(f"  {name:<28}{found[name]:>8.3f} s")
        missing = [n for n in IMPORTS if n not in found]
        if missing:
            print("  not imported by the audit: " + ", ".join(missing))
    return 1 if any(c.failures for c in contenders) else 0


if __name__ == "__main__":
    sys.exit(main())
