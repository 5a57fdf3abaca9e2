"""Fuzz campaign: mutate the sample and simulated logs and rigs, run the CLI on each, count.

    python benchmarks/fuzz_campaign.py --mutants 2000            # the long mode
    python benchmarks/fuzz_campaign.py --replay vlp16_bag-flip_bits-123456
    python benchmarks/fuzz_campaign.py --loaders 2000 --mutants 0   # the loaders class only
    python benchmarks/fuzz_campaign.py --outputs                 # every output flag x target

Prints the counts by exit code, the problems by cause (known open items of issue 10
listed apart from new ones), the slowest and largest runs; failing mutants are saved as
JSON replay records under --failures (default fuzz-failures/). Exit status 1 when any
problem has no known open cause.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "fuzz"))
sys.path.insert(1, str(Path(__file__).resolve().parents[1] / "tests"))  # hostile_configs

from campaign import (
    CI_SEED,
    KNOWN_OPEN,
    MAX_RSS_MB,
    Mutant,
    Outcome,
    classify,
    plan,
    run_campaign,
    save_failure,
)


def main() -> int:
    """Run the campaign and print its figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mutants", type=int, default=2000)
    parser.add_argument("--seed", type=int, default=CI_SEED)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--info-every", type=int, default=1, help="run info on every Nth mutant")
    parser.add_argument("--failures", type=Path, default=Path("fuzz-failures"))
    parser.add_argument("--replay", help="run one mutant by id and keep its files")
    parser.add_argument("--keep", type=Path, help="work directory to keep (default: a temp dir)")
    parser.add_argument(
        "--loaders", type=int, default=0, help="also run this many hostile config mutants"
    )
    parser.add_argument(
        "--outputs",
        action="store_true",
        help="run the outputs class instead: every output flag against every kind of target",
    )
    args = parser.parse_args()
    if args.outputs:
        return outputs_matrix(args.jobs, args.keep)
    if args.loaders:
        status = run_loaders(args.loaders, args.seed, args.jobs, args.failures)
        if not args.mutants:
            return status
    mutants = [Mutant.parse(args.replay)] if args.replay else plan(args.mutants, args.seed)
    root = args.keep or Path(tempfile.mkdtemp(prefix="syncaudit-fuzz-"))
    done = [0]
    start = time.monotonic()

    def progress(_m: Mutant, _o: Outcome) -> None:
        done[0] += 1
        if done[0] % 100 == 0:
            rate = done[0] / (time.monotonic() - start)
            print(f"  {done[0]}/{len(mutants)} mutants ({rate:.1f}/s)", file=sys.stderr)

    try:
        outcomes = run_campaign(
            mutants, root, jobs=args.jobs, info_every=args.info_every, on_done=progress
        )
    finally:
        if args.keep is None and not args.replay:
            shutil.rmtree(root, ignore_errors=True)
    wall = time.monotonic() - start
    return report(mutants, outcomes, wall, args.failures, replay=bool(args.replay), root=root)


def run_loaders(count: int, seed: int, jobs: int, failures: Path) -> int:
    """The loaders class: `count` hostile config files through the CLI; 1 on any problem."""
    import json

    from loader_campaign import loader_plan, run_loader_campaign

    mutants = loader_plan(count, seed)
    root = Path(tempfile.mkdtemp(prefix="syncaudit-loader-fuzz-"))
    start = time.monotonic()
    try:
        outcomes = run_loader_campaign(mutants, root, jobs=jobs)
        left = sorted(
            p.name
            for p in root.iterdir()
            if p.name not in outcomes or not outcomes[p.name].problems
        )
    finally:
        shutil.rmtree(root, ignore_errors=True)
    wall = time.monotonic() - start
    runs = [o.run for o in outcomes.values()]
    by_exit = Counter(f"{o.mutant.split('-')[1]} {o.run.exit_code}" for o in outcomes.values())
    by_problem = Counter(p for o in outcomes.values() for p, _ in o.problems)
    failing = [o for o in outcomes.values() if o.problems]
    for outcome in failing:
        failures.mkdir(parents=True, exist_ok=True)
        record = {"description": outcome.description, "problems": outcome.problems}
        (failures / f"{outcome.mutant}.json").write_text(json.dumps(record, indent=2))
    slow = max(runs, key=lambda r: r.seconds)
    big = max(runs, key=lambda r: r.max_rss_mb)
    print(f"loaders: {len(mutants)} mutants in {wall:.0f} s")
    print("exit codes: " + ", ".join(f"{k}: {v}" for k, v in sorted(by_exit.items())))
    print(f"mutants with problems: {len(failing)}; by problem: {dict(by_problem) or 'none'}")
    print(f"work folders left by passing mutants: {len(left)}")
    print(
        f"slowest run {slow.seconds:.1f} s ({' '.join(slow.argv[:1])}); "
        f"largest {big.max_rss_mb:.0f} MB (bound {MAX_RSS_MB:.0f} MB)"
    )
    return 1 if failing else 0


def outputs_matrix(jobs: int, keep: Path | None) -> int:
    """Every (output flag, existing target, --overwrite or not): print the counts, the failures."""
    from concurrent.futures import ThreadPoolExecutor

    from outputs_campaign import cases, real_data_present, run_case

    if not real_data_present():
        print("the real recordings of /work/shared/data are missing", file=sys.stderr)
        return 2
    root = keep or Path(tempfile.mkdtemp(prefix="syncaudit-outputs-"))
    todo = list(cases())
    start = time.monotonic()
    try:
        with ThreadPoolExecutor(max_workers=jobs) as pool:
            results = list(pool.map(lambda ic: run_case(ic[1], root / str(ic[0])), enumerate(todo)))
    finally:
        if keep is None:
            shutil.rmtree(root, ignore_errors=True)
    by_exit = Counter(f"exit {r.code}" for r in results)
    bad = [r for r in results if not r.ok]
    print(f"{len(results)} output cases in {time.monotonic() - start:.0f} s")
    print("exit codes: " + ", ".join(f"{k}: {v}" for k, v in sorted(by_exit.items())))
    changed = sum(not r.unchanged for r in results)
    left = sum(bool(r.leftovers) for r in results)
    print(f"failing: {len(bad)} (bytes changed: {changed}, leftovers: {left})")
    for r in bad:
        first = r.stderr.strip().splitlines()[:1]
        print(f"  {r.case.id}: exit {r.code} (expected {sorted(r.expected)}) {first}")
    return 1 if bad else 0


def report(
    mutants: list[Mutant],
    outcomes: dict[str, Outcome],
    wall_s: float,
    failures: Path,
    *,
    replay: bool,
    root: Path,
) -> int:
    """Print the counts; save failing mutants; 1 where a problem has no known cause."""
    by_exit: Counter[str] = Counter()
    by_cause: Counter[str] = Counter()
    by_problem: Counter[str] = Counter()
    failing = 0
    new = 0
    runs = []
    for mutant in mutants:
        outcome = outcomes[mutant.id]
        for run in (outcome.audit, outcome.info):
            if run is not None and run.argv:
                by_exit[f"{run.argv[0]} {run.exit_code}"] += 1
                runs.append(run)
        problems = classify(mutant, outcome)
        if problems:
            failing += 1
            save_failure(outcome, mutant, failures)
        if any(cause is None for _, _, cause in problems):
            new += 1
        for problem, _, cause in problems:
            by_problem[problem] += 1
            by_cause[cause or f"NEW:{problem}"] += 1
        if replay:
            print(f"{mutant.id}: {outcome.description}")
            for run in (outcome.audit, outcome.info):
                if run is not None:
                    print(
                        f"  {' '.join(run.argv[:1])}: exit {run.exit_code}, {run.seconds:.2f} s, "
                        f"{run.max_rss_mb:.0f} MB: {run.stderr.strip()[:400]}"
                    )
            for problem in problems:
                print(f"  problem: {problem}")
            print(f"  files kept in {root / mutant.id}")
    items = {c.key: f"item {c.item} ({c.owner})" for c in KNOWN_OPEN}
    print(f"{len(mutants)} mutants, {len(runs)} CLI runs in {wall_s:.0f} s")
    print("exit codes: " + ", ".join(f"{k}: {v}" for k, v in sorted(by_exit.items())))
    print(f"mutants with problems: {failing} ({new} with a cause not known open)")
    for cause, count in by_cause.most_common():
        print(f"  {cause}: {count}" + (f"  [{items[cause]}]" if cause in items else ""))
    if runs:
        slow = max(runs, key=lambda r: r.seconds)
        big = max(runs, key=lambda r: r.max_rss_mb)
        print(
            f"slowest run {slow.seconds:.1f} s; largest {big.max_rss_mb:.0f} MB "
            f"(bound {MAX_RSS_MB:.0f} MB)"
        )
    if failing:
        print(f"failing mutants saved in {failures}/ (replay: --replay <id>)")
    return 1 if new else 0


if __name__ == "__main__":
    sys.exit(main())
