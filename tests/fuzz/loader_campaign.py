"""The fuzz campaign's loaders class: hostile config files, mutated, given to the real CLI.

A loader mutant is (loader, seed): the seed picks a hostile kind (`hostile_configs`), a
mutation (as made, bytes flipped, cut short, an alias bomb of other levels and widths, or
spliced after a valid file of that loader) and the command that reads the file (`info
--rig`, `gate --policy`, a `gate` manifest, `calib --config`/`--extrinsics`, a bag's
`metadata.yaml` under `info`). The rules are the log campaign's (`campaign.check`: a
documented exit, one line, no traceback, under MAX_RSS_MB, no process left), plus: a file
refused (exit 2 or 6) within REFUSAL_S of wall time, and nothing left in the work folder.
"""

from __future__ import annotations

import random
import shutil
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

from campaign import DOCUMENTED_EXITS, MAX_RSS_MB, SAMPLES, TIMEOUT_S, Run, run_cli

from hostile_configs import HOSTILE_KINDS, alias_bomb, csv_text, json_text, yaml_file

LOADERS = (
    "rig",
    "policy",
    "manifest_jsonl",
    "manifest_csv",
    "calib_config",
    "extrinsics",
    "bag_metadata",
)
MUTATIONS = ("as_is", "flip", "truncate", "bomb_shape", "splice")
REFUSAL_S = 5.0
"""Wall time a refusal may take, interpreter start included, on the shared 2-core machine
(the parse itself is bounded at 1 s of CPU by tests/config/test_hostile_loaders.py)."""

POLICY = "valid_policy.yaml"
MCAP = SAMPLES / "vlp16_three_cameras.mcap"
BAG = SAMPLES / "vlp16_short.bag"
ROS2 = SAMPLES / "vlp16_short_ros2"
VALID = {
    "rig": (SAMPLES / "vlp16_three_cameras.mcap.rig.yaml").read_bytes(),
    "policy": b"defaults:\n  max_error_mean_us: 500\n",
    "manifest_jsonl": b'{"path": "' + str(MCAP).encode() + b'"}\n',
    "manifest_csv": b"path\n" + str(MCAP).encode() + b"\n",
    "calib_config": b"max_pairs: 3\n",
    "extrinsics": b"extrinsics: {}\n",
    "bag_metadata": (ROS2 / "metadata.yaml").read_bytes(),
}


@dataclass(frozen=True, slots=True)
class LoaderMutant:
    """A replayable loader mutant."""

    loader: str
    seed: int

    @property
    def id(self) -> str:
        return f"loader-{self.loader}-{self.seed}"


def loader_plan(count: int, seed: int) -> list[LoaderMutant]:
    """`count` mutants, every loader in turn."""
    rng = random.Random(seed)
    return [LoaderMutant(LOADERS[n % len(LOADERS)], rng.randrange(10**6)) for n in range(count)]


def hostile_bytes(loader: str, rng: random.Random) -> tuple[bytes, str]:
    """A mutated hostile file for `loader` and what was done."""
    kind = rng.choice(HOSTILE_KINDS)
    mutation = rng.choice(MUTATIONS)
    make = (
        json_text
        if loader == "manifest_jsonl"
        else csv_text
        if loader == "manifest_csv"
        else yaml_file
    )
    data = make(kind)
    if mutation == "flip":
        raw = bytearray(data)
        for _ in range(rng.randint(1, 8)):
            raw[rng.randrange(len(raw))] = rng.randrange(256)
        data = bytes(raw)
    elif mutation == "truncate":
        data = data[: rng.randrange(1, len(data) + 1)]
    elif mutation == "bomb_shape" and make is yaml_file:
        levels, width = rng.randint(2, 14), rng.randint(2, 14)
        kind = f"alias_bomb {levels}x{width}"
        data = alias_bomb(levels, width)
    elif mutation == "splice":
        data = VALID[loader] + (b"\n" if not VALID[loader].endswith(b"\n") else b"") + data
    return data, f"{kind}, {mutation}"


def command(loader: str, path: Path) -> list[str]:
    """The CLI run that reads `path` as `loader`."""
    return {
        "rig": ["info", str(MCAP), "--rig", str(path)],
        "policy": ["gate", str(MCAP), "--policy", str(path), "--no-db"],
        "manifest_jsonl": ["gate", str(path), "--no-db", "--policy", str(path.parent / POLICY)],
        "manifest_csv": ["gate", str(path), "--no-db", "--policy", str(path.parent / POLICY)],
        "calib_config": ["calib", str(BAG), "--config", str(path)],
        "extrinsics": ["calib", str(BAG), "--extrinsics", str(path)],
        "bag_metadata": ["info", str(path.parent)],
    }[loader]


@dataclass(slots=True)
class LoaderOutcome:
    """One loader mutant's run and problems."""

    mutant: str
    description: str
    run: Run
    problems: list[tuple[str, str]]


def build(mutant: LoaderMutant, work: Path) -> tuple[Path, str]:
    """Write the mutant's file into `work` (a copy of the ROS 2 sample for metadata.yaml)."""
    rng = random.Random(mutant.seed)
    data, what = hostile_bytes(mutant.loader, rng)
    names = {"manifest_jsonl": "logs.jsonl", "manifest_csv": "logs.csv"}
    if mutant.loader == "bag_metadata":
        bag = work / "bag"
        shutil.copytree(ROS2, bag)
        path = bag / "metadata.yaml"
    else:
        path = work / names.get(mutant.loader, f"{mutant.loader}.yaml")
        (work / POLICY).write_text("{}\n")  # the gate of a manifest needs one
    path.write_bytes(data)
    return path, what


def run_loader_mutant(mutant: LoaderMutant, work: Path) -> LoaderOutcome:
    """Build, run, check one mutant in `work`."""
    work.mkdir(parents=True, exist_ok=True)
    path, what = build(mutant, work)
    before = sorted(p.relative_to(work).as_posix() for p in work.rglob("*"))
    run = run_cli(command(mutant.loader, path), cwd=work)
    problems: list[tuple[str, str]] = []
    if run.exit_code is None:
        problems.append(("timeout", f"over {TIMEOUT_S:.0f} s"))
    else:
        if run.exit_code not in DOCUMENTED_EXITS or run.exit_code == 70:
            problems.append(("bad-exit", f"exit {run.exit_code}: {run.stderr.strip()[:300]}"))
        if "Traceback" in run.stderr:
            problems.append(("traceback", run.stderr.strip().splitlines()[-1][:300]))
        errors = [ln for ln in run.stderr.splitlines() if ln.strip()]
        if run.exit_code in (2, 6) and (len(errors) != 1 or not errors[0].startswith("error:")):
            problems.append(("not-one-line", f"{len(errors)} stderr lines"))
        if run.exit_code in (2, 6) and run.seconds > REFUSAL_S:
            problems.append(("slow-refusal", f"{run.seconds:.1f} s"))
    if run.max_rss_mb > MAX_RSS_MB:
        problems.append(("memory", f"{run.max_rss_mb:.0f} MB"))
    if run.orphans:
        problems.append(("orphans", f"processes left alive {run.orphans}"))
    after = sorted(p.relative_to(work).as_posix() for p in work.rglob("*") if p.name != ".measured")
    if after != before:
        problems.append(("leftovers", f"{sorted(set(after) - set(before))}"))
    return LoaderOutcome(mutant.id, what, run, problems)


def run_loader_campaign(
    mutants: list[LoaderMutant], root: Path, *, jobs: int = 2
) -> dict[str, LoaderOutcome]:
    """Run every mutant, `jobs` at a time, each in `root/<id>` (removed when it passes)."""

    def one(mutant: LoaderMutant) -> LoaderOutcome:
        work = root / mutant.id
        if work.exists():
            shutil.rmtree(work)
        outcome = run_loader_mutant(mutant, work)
        if not outcome.problems:
            shutil.rmtree(work, ignore_errors=True)
        return outcome

    with ThreadPoolExecutor(max_workers=jobs) as pool:
        return {o.mutant: o for o in pool.map(one, mutants)}
