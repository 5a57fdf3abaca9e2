"""The outputs class of the fuzz campaign: every output flag against every kind of target.

A case is one output option (`audit --html`, `simulate sync OUT`, `gate --html DIR`, ...)
aimed at one kind of existing target (a real recording from /work/shared/data, a foreign
folder or file, the tool's own output, the run's input, a symbolic link to any of these),
with and without `--overwrite`. Expected, whatever the flags:

- a target the tool did not write: exit 8, and every byte of the work folder unchanged;
- the run's input (or a link to it): exit 64, unchanged;
- the tool's own output: exit 8 without `--overwrite`; with it, the same exit as the first
  run that wrote it.

`run_case` hashes every file of the case's folder (links as their targets' names) before
and after the run, and looks for leftover temporaries.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
SAMPLES = REPO / "sample_logs"
LOG = SAMPLES / "vlp16_short.bag"
RIG = SAMPLES / "vlp16_short.bag.rig.yaml"
DATA = Path("/work/shared/data")
REAL_ROSBAG2 = DATA / "lidar" / "hesai_40p" / "1673400149412331409"
REAL_BAG1 = DATA / "lidar" / "ouster_os1_512x10" / "512x10_raw.bag"
REAL_MCAP = DATA / "mcap-conformance" / "OneMetadata" / "OneMetadata.mcap"
REAL_PCD = DATA / "lidar" / "hesai_40p" / "1673400149711850138.pcd"
TIMEOUT_S = 180.0

KINDS = (
    "input",
    "link_input",
    "real_rosbag2",
    "real_bag1",
    "real_mcap",
    "real_pcd",
    "foreign_folder",
    "foreign_file",
    "user_index",
    "link_real",
    "link_foreign",
    "own",
)
"""Kinds of existing target; `own` is the tool's output from a first run of the case."""
INPUT_KINDS = ("input", "link_input")


def real_data_present() -> bool:
    """Whether the real recordings of /work/shared/data are there."""
    return all(p.exists() for p in (REAL_ROSBAG2, REAL_BAG1, REAL_MCAP, REAL_PCD))


@dataclass(frozen=True)
class Flag:
    """One output option: the command line with its target, and what kind of path it takes."""

    name: str
    argv: Callable[[Path, Path], list[str]]
    """(target, work folder) -> arguments after `syncaudit`."""
    target_name: str
    input_path: Callable[[Path], Path] | None = None
    """The run's input a target of kind `input` names (None: the command has none)."""
    needs: tuple[str, ...] = ()
    """Prepared files in the work folder the command reads (`policy`, `db`)."""


def _audit(option: str) -> Callable[[Path, Path], list[str]]:
    return lambda t, w: ["audit", str(w / "log.bag"), "--rig", str(RIG), option, str(t)]


def _gate(option: str) -> Callable[[Path, Path], list[str]]:
    return lambda t, w: [
        "gate", str(w / "log.bag"), "--policy", str(w / "policy.yaml"), "--no-db", option, str(t)
    ]  # fmt: skip


def _report(option: str) -> Callable[[Path, Path], list[str]]:
    return lambda t, w: ["fleet", "report", "--db", str(w / "fleet.duckdb"), option, str(t)]


def _log(w: Path) -> Path:
    return w / "log.bag"


FLAGS: tuple[Flag, ...] = (
    Flag("audit --json-out", _audit("--json-out"), "out.json", _log),
    Flag("audit --html", _audit("--html"), "out.html", _log),
    Flag("audit --csv", _audit("--csv"), "out.csv", _log),
    Flag("audit --parquet", _audit("--parquet"), "out.parquet", _log),
    Flag("audit --pairings .mcap", _audit("--pairings"), "out.mcap", _log),
    Flag("audit --pairings .bag", _audit("--pairings"), "out.bag", _log),
    Flag("audit --pairings folder", _audit("--pairings"), "outbag", _log),
    Flag("rig -o", lambda t, w: ["rig", str(w / "log.bag"), "-o", str(t)], "rig.yaml", _log),
    Flag("simulate sync", lambda t, w: ["simulate", "sync", str(t), "--duration", "1"], "sim"),
    Flag(
        "simulate sync .mcap",
        lambda t, w: ["simulate", "sync", str(t), "--duration", "1"],
        "sim.mcap",
    ),
    Flag("simulate calib", lambda t, w: ["simulate", "calib", str(t)], "calib"),
    Flag("gate --junit", _gate("--junit"), "gate.xml", _log, ("policy",)),
    Flag("gate --summary", _gate("--summary"), "gate.md", _log, ("policy",)),
    Flag("gate --json-out", _gate("--json-out"), "gate.json", _log, ("policy",)),
    Flag("gate --html", _gate("--html"), "gate-html", _log, ("policy",)),
    Flag(
        "gate --init -o",
        # --accept-bad: the fuzz log fails the default thresholds, and --init refuses such
        # logs before it writes anything; the case is about the output, not the doubt.
        lambda t, w: ["gate", "--init", str(w / "log.bag"), "-o", str(t), "--accept-bad"],
        "policy-out.yaml",
        _log,
    ),
    Flag("fleet report --html", _report("--html"), "dash", lambda w: w / "fleet.duckdb", ("db",)),
    Flag("fleet report --csv", _report("--csv"), "f.csv", lambda w: w / "fleet.duckdb", ("db",)),
    Flag(
        "fleet report --parquet",
        _report("--parquet"),
        "f.parquet",
        lambda w: w / "fleet.duckdb",
        ("db",),
    ),
)


@dataclass(frozen=True)
class Case:
    """One output flag against one kind of existing target, with or without --overwrite."""

    flag: Flag
    kind: str
    overwrite: bool

    @property
    def id(self) -> str:
        return f"{self.flag.name} <- {self.kind}{' --overwrite' if self.overwrite else ''}"


@dataclass
class CaseResult:
    """What one case did: its exit codes and whether the folder kept its bytes."""

    case: Case
    code: int
    expected: set[int]
    unchanged: bool
    """For refusals: every file's bytes and every link as before."""
    leftovers: list[str] = field(default_factory=list)
    stderr: str = ""

    @property
    def ok(self) -> bool:
        return self.code in self.expected and self.unchanged and not self.leftovers


def cases(kinds: tuple[str, ...] = KINDS) -> Iterator[Case]:
    """Every (flag, kind, overwrite) that applies (input kinds only where there is one)."""
    for flag in FLAGS:
        for kind in kinds:
            if kind in INPUT_KINDS and flag.input_path is None:
                continue
            for overwrite in (False, True):
                yield Case(flag, kind, overwrite)


def snapshot(folder: Path) -> dict[str, str]:
    """Every entry under `folder`: a file's SHA-256, a link's target, a folder's mark."""
    found: dict[str, str] = {}
    for root, dirs, files in os.walk(folder):
        for name in dirs + files:
            path = Path(root) / name
            rel = str(path.relative_to(folder))
            if path.is_symlink():
                found[rel] = "-> " + os.readlink(path)
            elif path.is_dir():
                found[rel] = "dir"
            else:
                found[rel] = hashlib.sha256(path.read_bytes()).hexdigest()
    return found


def _cli(argv: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "SYNCAUDIT_DEBUG": ""}
    return subprocess.run(
        [sys.executable, "-m", "syncaudit", *argv],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
        check=False,
    )


def prepare(work: Path, flag: Flag) -> None:
    """The case's folder: a copy of the log (an input it may name) and what the flag needs."""
    work.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(LOG, work / "log.bag")
    if "policy" in flag.needs or "db" in flag.needs:
        (work / "policy.yaml").write_text("{}\n")
    if "db" in flag.needs:
        done = _cli(
            ["gate", str(work / "log.bag"), "--policy", str(work / "policy.yaml"),
             "--db", str(work / "fleet.duckdb")],
            work,
        )  # fmt: skip
        if done.returncode not in (0, 10):  # 10: the log fails the policy, still recorded
            raise RuntimeError(f"preparing the results database: {done.stderr.strip()}")


def place(work: Path, flag: Flag, kind: str) -> Path:
    """Put an existing target of `kind` where the flag writes; return the path to give it."""
    target = work / flag.target_name
    elsewhere = work / "elsewhere"
    elsewhere.mkdir(exist_ok=True)
    if kind == "real_rosbag2":
        shutil.copytree(REAL_ROSBAG2, target)
    elif kind == "real_bag1":
        shutil.copyfile(REAL_BAG1, target)
    elif kind == "real_mcap":
        shutil.copyfile(REAL_MCAP, target)
    elif kind == "real_pcd":
        shutil.copyfile(REAL_PCD, target)
    elif kind == "foreign_folder":
        target.mkdir()
        (target / "notes.txt").write_text("my notes\n")
    elif kind == "foreign_file":
        target.write_text("a user's own file\n")
    elif kind == "user_index":
        target.mkdir()
        (target / "index.html").write_text("<!doctype html><p>my own page</p>\n")
    elif kind == "input":
        assert flag.input_path is not None
        return flag.input_path(work)
    elif kind == "link_real":
        shutil.copytree(REAL_ROSBAG2, elsewhere / "recording")
        target.symlink_to(elsewhere / "recording")
    elif kind == "link_foreign":
        (elsewhere / "mine.txt").write_text("a user's own file\n")
        target.symlink_to(elsewhere / "mine.txt")
    elif kind == "link_input":
        assert flag.input_path is not None
        target.symlink_to(flag.input_path(work))
    elif kind != "own":
        raise ValueError(kind)
    return target


def _leftovers(work: Path) -> list[str]:
    return sorted(
        str(p.relative_to(work))
        for p in work.rglob("*")
        if p.name.startswith(".syncaudit-") or p.name.endswith((".lock", ".tmp"))
    )


def run_case(case: Case, work: Path) -> CaseResult:
    """Run one case in the fresh folder `work` (made here) and judge it."""
    prepare(work, case.flag)
    target = place(work, case.flag, case.kind)
    first_code: int | None = None
    if case.kind == "own":
        first = _cli(case.flag.argv(target, work), work)
        first_code = first.returncode
        if first_code not in (0, 10) or not (target.exists() or target.is_symlink()):
            return CaseResult(case, first_code, {0, 10}, False, [], first.stderr.strip())
    before = snapshot(work)
    argv = case.flag.argv(target, work) + (["--overwrite"] if case.overwrite else [])
    done = _cli(argv, work)
    after = snapshot(work)
    if case.kind in INPUT_KINDS:
        expected = {64}
    elif case.kind == "own" and case.overwrite:
        assert first_code is not None
        expected = {first_code}
    else:
        expected = {8}
    replaced = case.kind == "own" and case.overwrite
    unchanged = replaced or before == after
    return CaseResult(case, done.returncode, expected, unchanged, _leftovers(work), done.stderr)
