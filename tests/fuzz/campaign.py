"""The fuzz campaign: mutants of real logs and rigs, each run through the real CLI.

A mutant is (base log, mutator, seed): `build` writes it into a directory, `run_mutant`
runs `syncaudit audit` (every output requested into a fresh directory) and `syncaudit
info` on it in subprocesses of their own session, and `check` lists what went wrong:
an exit code outside the documented set, a traceback, an error of more than one line,
more than `MAX_RSS_MB` of memory (the run's process tree, from wait4), more than
`TIMEOUT_S`, outputs or temporaries left by a failed run, a changed input, a process
left alive, `info` exiting 0 where `audit` found the LiDAR damaged. Problems whose
cause is a known open item of issue 10 (fixed on another branch) are listed in
`KNOWN_OPEN`, one place, with the owning item; the tests xfail on those only.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path

import mutators as mu
from rig_mutators import mutate_rig

REPO = Path(__file__).resolve().parents[2]
SAMPLES = REPO / "sample_logs"
DOCUMENTED_EXITS = frozenset({0, 2, 3, 4, 5, 6, 7, 8, 10})
MAX_RSS_MB = 500.0
TIMEOUT_S = 30.0
CI_SEED = 20261130
CI_MUTANTS = 110
LONG_MUTANTS = 2000

BASES: dict[str, str] = {
    "vlp16_mcap": "vlp16_three_cameras.mcap",
    "pandar_mcap": "pandar40p_adaptive.mcap",
    "vlp16_db3": "vlp16_short_ros2",
    "vlp16_bag": "vlp16_short.bag",
    "xt32_ros1_mcap": "sim:PandarXT32:mcap-ros1",
    "vlp32c_db3": "sim:VLP-32C:db3",
}
"""Sample logs of the repo, and small simulated logs (made once per campaign)."""

MCAP_MUTATORS = (
    "truncate_record",
    "truncate_any",
    "flip_bits",
    "flip_chunk_bits",
    "hostile_length",
    "hostile_chunk",
    "bad_encoding",
    "cut_payload",
    "flip_payload",
    "huge_log_time",
    "rig",
)
DB3_MUTATORS = (
    "truncate_pages",
    "flip_bits",
    "bad_encoding",
    "cut_payload",
    "flip_payload",
    "huge_log_time",
    "metadata",
    "rig",
)
BAG_MUTATORS = (
    "truncate_record",
    "truncate_any",
    "flip_bits",
    "flip_chunk_bits",
    "hostile_length",
    "rig",
)


def base_kind(base: str) -> str:
    """'bag', 'db3' (a rosbag2 sqlite directory) or 'mcap'."""
    name = BASES[base]
    if name.endswith(".bag"):
        return "bag"
    if name.endswith((".mcap", ":mcap", ":mcap-ros1")):
        return "mcap"
    return "db3"


def mutators_for(base: str) -> tuple[str, ...]:
    """The mutators that apply to a base log."""
    return {"bag": BAG_MUTATORS, "db3": DB3_MUTATORS, "mcap": MCAP_MUTATORS}[base_kind(base)]


@dataclass(frozen=True, slots=True)
class Mutant:
    """A replayable mutant: base log, mutator, seed."""

    base: str
    mutator: str
    seed: int

    @property
    def id(self) -> str:
        """Stable id, used in test names and failure files."""
        return f"{self.base}-{self.mutator}-{self.seed}"

    @classmethod
    def parse(cls, text: str) -> Mutant:
        """The mutant an id names."""
        base, rest = next((b, text[len(b) + 1 :]) for b in BASES if text.startswith(b + "-"))
        mutator, seed = rest.rsplit("-", 1)
        return cls(base, mutator, int(seed))


def plan(count: int, seed: int = CI_SEED) -> list[Mutant]:
    """`count` mutants spread over every base and mutator, deterministic in `seed`.

    The first pass takes every (base, mutator) pair once, so even a short run covers
    every record class and mutation kind; later ones are drawn at random.
    """
    rng = random.Random(seed)
    pairs = [(b, m) for b in BASES for m in mutators_for(b)]
    out: list[Mutant] = []
    while len(out) < count:
        batch = pairs if not out else [rng.choice(pairs) for _ in pairs]
        out.extend(Mutant(b, m, rng.randrange(10**6)) for b, m in batch)
    return out[:count]


# ---- bases -------------------------------------------------------------------------------


def base_paths(base: str, cache: Path) -> tuple[Path, Path]:
    """(log, rig) of a base, simulating it into `cache` the first time."""
    name = BASES[base]
    if not name.startswith("sim:"):
        return SAMPLES / name, SAMPLES / f"{name}.rig.yaml"
    _, lidar, fmt = name.split(":")
    out = cache / (base if fmt == "db3" else f"{base}.mcap")  # a .db3 bag is a directory
    rig = cache / f"{out.name}.rig.yaml"
    if not rig.exists():
        subprocess.run(
            [
                *syncaudit_cmd(),
                "simulate",
                "sync",
                str(out),
                "--lidar",
                lidar,
                "--format",
                fmt,
                "--duration",
                "1.5",
                "--seed",
                "7",
                "--overwrite",
            ],
            check=True,
            capture_output=True,
        )
    return out, rig


def syncaudit_cmd() -> list[str]:
    """The CLI as a subprocess command (this interpreter's installed package)."""
    return [sys.executable, "-m", "syncaudit.cli"]


# ---- building a mutant ---------------------------------------------------------------------


def build(mutant: Mutant, cache: Path, work: Path) -> tuple[Path, Path, str]:
    """Write the mutant's log and rig into `work`; return them and what was done."""
    rng = random.Random(mutant.seed)
    src_log, src_rig = base_paths(mutant.base, cache)
    log = work / src_log.name
    rig = work / "rig.yaml"
    shutil.copyfile(src_rig, rig)
    m = mutant.mutator
    if m == "rig":
        mu.copy_log(src_log, log)
        raw, what = mutate_rig(src_rig.read_text(), rng)
        rig.write_bytes(raw)
        return log, rig, what
    if src_log.is_dir() or src_log.suffix == ".db3":
        mu.copy_log(src_log, log)
        return log, rig, _mutate_db3(m, log, rng)
    data = src_log.read_bytes()
    if src_log.suffix == ".bag":
        records = mu.bag_records(data)
        u64 = False
    else:
        records = mu.mcap_records(data)
        u64 = True
    chunk_kind = "chunk"
    what: str
    if m == "truncate_record":
        data, what = mu.truncate_at_record(data, records, rng)
    elif m == "truncate_any":
        data, what = mu.truncate_anywhere(data, rng)
    elif m == "flip_bits":
        data, what = mu.flip_bits(data, rng)
    elif m == "flip_chunk_bits":
        rec = rng.choice([r for r in records if r.kind == chunk_kind])
        data, what = mu.flip_bits(data, rng, start=rec.offset, end=rec.offset + min(rec.size, 256))
        what = f"chunk header at {rec.offset}: {what}"
    elif m == "hostile_length":
        data, what = mu.hostile_length(data, records, rng, u64=u64)
    elif m == "hostile_chunk":
        data, what = mu.hostile_chunk_field(data, records, rng)
    else:
        return log, rig, _rewrite_mcap(m, src_log, log, rng)
    log.write_bytes(data)
    return log, rig, what


def _rewrite_mcap(m: str, src: Path, dst: Path, rng: random.Random) -> str:
    topics = mu.mcap_topics(src)
    cls, topic = mu.pick_topic(topics, rng)
    if m == "bad_encoding":
        encoding = rng.choice(mu.BAD_ENCODINGS)
        mu.rewrite_mcap(src, dst, encoding_of=lambda t, _m, e: encoding if t == topic else e)
        return f"{cls} topic {topic}: message encoding -> {encoding!r}"
    if m == "huge_log_time":
        value = rng.choice((2**63, 2**63 + 12345, 2**64 - 1, 0))
        nth = rng.randrange(1, 50)
        seen = [0]

        def time_of(t: str, _i: int, log_time: int) -> int:
            if t != topic:
                return log_time
            seen[0] += 1
            return value if seen[0] == nth else log_time

        mu.rewrite_mcap(src, dst, time_of=time_of)
        return f"{cls} topic {topic}: message {nth} log time -> {value}"
    every = rng.choice((1, 1, 3, 50))
    compression = rng.choice(("zstd", "lz4", "none"))

    def payload_of(t: str, _m: str, i: int, data: bytes) -> bytes:
        if t != topic or i % every:
            return data
        if m == "cut_payload":
            return mu.cut_payload(data, rng)
        return mu.flip_bits(data, rng, flips=rng.randint(1, 4))[0] if data else data

    mu.rewrite_mcap(src, dst, payload_of=payload_of, compression=compression)
    how = "cut short" if m == "cut_payload" else "bit-flipped"
    return f"{cls} topic {topic}: every {every} message {how} ({compression} chunks)"


def _mutate_db3(m: str, bag: Path, rng: random.Random) -> str:
    db = mu.db3_file(bag)
    if m == "truncate_pages":
        size = db.stat().st_size
        page = 4096
        cut = rng.choice((rng.randrange(0, size // page) * page, rng.randrange(0, size)))
        with db.open("r+b") as f:
            f.truncate(cut)
        return f"{db.name} truncated to {cut} of {size} bytes"
    if m == "flip_bits":
        data, what = mu.flip_bits(db.read_bytes(), rng)
        db.write_bytes(data)
        return f"{db.name}: {what}"
    if m == "metadata":
        meta = bag / "metadata.yaml"
        choice = rng.choice(("cut", "flip", "delete", "empty"))
        raw = meta.read_bytes()
        if choice == "cut":
            meta.write_bytes(raw[: rng.randrange(len(raw))])
        elif choice == "flip":
            meta.write_bytes(mu.flip_bits(raw, rng)[0])
        elif choice == "delete":
            meta.unlink()
        else:
            meta.write_bytes(b"")
        return f"metadata.yaml: {choice}"
    topics = [(n, t) for _, n, t in mu.db3_topics(bag)]
    cls, topic = mu.pick_topic(topics, rng)
    if m == "bad_encoding":
        encoding = rng.choice(mu.BAD_ENCODINGS)
        mu.db3_sql(
            bag, [("UPDATE topics SET serialization_format=? WHERE name=?", (encoding, topic))]
        )
        return f"{cls} topic {topic}: serialization_format -> {encoding!r}"
    if m == "huge_log_time":
        value = rng.choice((2**63 - 1, -1, -(2**63)))
        mu.db3_sql(
            bag,
            [
                (
                    "UPDATE messages SET timestamp=? WHERE id=(SELECT min(id) FROM messages "
                    "WHERE topic_id=(SELECT id FROM topics WHERE name=?))",
                    (value, topic),
                )
            ],
        )
        return f"{cls} topic {topic}: first message timestamp -> {value}"
    every = rng.choice((1, 1, 3))
    con_sql = "SELECT m.id, m.data FROM messages m JOIN topics t ON t.id=m.topic_id WHERE t.name=?"
    import sqlite3

    con = sqlite3.connect(db)
    try:
        rows = con.execute(con_sql, (topic,)).fetchall()
        for k, (mid, data) in enumerate(rows):
            if k % every:
                continue
            data = bytes(data)
            if m == "cut_payload":
                new = mu.cut_payload(data, rng)
            else:
                new = mu.flip_bits(data, rng, flips=rng.randint(1, 4))[0] if data else data
            con.execute("UPDATE messages SET data=? WHERE id=?", (new, mid))
        con.commit()
    finally:
        con.close()
    how = "cut short" if m == "cut_payload" else "bit-flipped"
    return f"{cls} topic {topic}: every {every} message {how}"


# ---- running -------------------------------------------------------------------------------


@dataclass(slots=True)
class Run:
    """One CLI run: what it printed and what it cost."""

    argv: list[str]
    exit_code: int | None
    stderr: str
    seconds: float
    max_rss_mb: float
    orphans: list[int] = field(default_factory=list)


_MEASURE = """
import os, sys
pid = os.fork()
if pid == 0:
    try:
        os.execvp(sys.argv[2], sys.argv[2:])
    finally:
        os._exit(127)
_, status, usage = os.wait4(pid, 0)
with open(sys.argv[1], "w") as out:
    out.write(f"{os.waitstatus_to_exitcode(status)} {usage.ru_maxrss}")
"""
"""Runs the CLI as the child of a small interpreter and writes its exit code and peak RSS.

Linux keeps a process's peak RSS across exec, and a child forked from this (test) process
starts with this process's resident pages: measured directly, the CLI's peak would be
pytest's size, not its own (a full test run's pytest passed 500 MB). Forked from the
small shim, the CLI's own peak is what wait4 reports."""


def run_cli(args: list[str], *, cwd: Path, timeout_s: float = TIMEOUT_S) -> Run:
    """Run the CLI in a session of its own; memory from wait4 (in a shim), orphans from /proc."""
    argv = [*syncaudit_cmd(), *args]
    env = {**os.environ, "COLUMNS": "200", "SYNCAUDIT_DEBUG": ""}
    env.pop("SYNCAUDIT_DEBUG")
    measured = cwd / ".measured"
    measured.unlink(missing_ok=True)
    start = time.monotonic()
    with open(cwd / ".stderr", "w+b") as err:
        proc = subprocess.Popen(
            [sys.executable, "-c", _MEASURE, str(measured), *argv],
            cwd=cwd,
            stdout=subprocess.DEVNULL,
            stderr=err,
            stdin=subprocess.DEVNULL,
            env=env,
            start_new_session=True,
        )
        code: int | None = None
        rss_kb = 0
        while True:
            pid, status, _ = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                code = os.waitstatus_to_exitcode(status)
                break
            if time.monotonic() - start > timeout_s:
                _kill_session(proc.pid)
                os.wait4(proc.pid, 0)
                break
            time.sleep(0.01)
        proc.returncode = -1  # reaped above; keep Popen from waiting again
        seconds = time.monotonic() - start
        if code is not None and measured.exists():
            cli_code, cli_rss_kb = measured.read_text().split()
            code, rss_kb = int(cli_code), int(cli_rss_kb)
            measured.unlink()
        orphans = _session_members(proc.pid)
        if orphans:
            _kill_session(proc.pid)
        err.seek(0)
        stderr = err.read().decode(errors="replace")
    (cwd / ".stderr").unlink()
    return Run(args, code, stderr, seconds, rss_kb / 1024, orphans)


_PF_EXITING = 0x4
"""/proc/PID/stat flags: the process is in the kernel's exit path."""
_SIGKILL_BIT = 1 << (signal.SIGKILL - 1)


def _session_members(sid: int) -> list[int]:
    """Processes still alive in session `sid` (workers the run left behind).

    A worker already killed is not left behind, even where a loaded machine has not yet
    let it run its exit: the kernel turns a fatal signal (the parent's PR_SET_PDEATHSIG
    SIGKILL, its SIGTERM) into a pending SIGKILL at once, and marks a process exiting
    before it becomes a zombie. Without this, such a worker counted as an orphan.
    """
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if int(fields[3]) == sid and fields[0] not in "ZX" and not _dying(stat.parent, fields):
            out.append(int(stat.parent.name))
    return out


def _dying(proc: Path, fields: list[str]) -> bool:
    """Whether a process is exiting or has a SIGKILL pending (its end is certain)."""
    if int(fields[6]) & _PF_EXITING:
        return True
    try:
        status = (proc / "status").read_text()
    except OSError:
        return True  # gone since its stat was read
    for line in status.splitlines():
        key, _, value = line.partition(":")
        if key in ("SigPnd", "ShdPnd") and int(value, 16) & _SIGKILL_BIT:
            return True
    return False


def _kill_session(sid: int) -> None:
    for pid in [sid, *_session_members(sid)]:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)


def _digest(path: Path) -> str:
    h = hashlib.sha256()
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    for f in files:
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.hexdigest()


@dataclass(slots=True)
class Outcome:
    """A mutant's runs and the problems found, each as (cause, detail)."""

    mutant: str
    description: str
    audit: Run
    info: Run | None
    problems: list[tuple[str, str]]

    def to_json(self) -> dict[str, object]:
        """JSON form for the failure files and the campaign summary."""
        return asdict(self)


OUTPUTS = ("audit.json", "frames.csv", ".frames.csv.syncaudit", "report.html", "pairings.mcap")
"""What a successful audit writes (the CSV's mark is its sidecar: docs/outputs.md)."""


def run_mutant(mutant: Mutant, cache: Path, work: Path, *, with_info: bool = True) -> Outcome:
    """Build the mutant in `work`, run audit (and info), check every rule."""
    work.mkdir(parents=True, exist_ok=True)
    try:
        log, rig, what = build(mutant, cache, work)
    except Exception as exc:  # the mutator itself failed: a harness bug, reported as one
        empty = Run([], None, f"{type(exc).__name__}: {exc}", 0.0, 0.0)
        return Outcome(mutant.id, "mutator failed", empty, None, [("harness", str(exc))])
    before = _digest(log), _digest(rig)
    out = work / "out"
    out.mkdir()
    audit = run_cli(
        [
            "audit",
            str(log),
            "--rig",
            str(rig),
            "--json-out",
            str(out / OUTPUTS[0]),
            "--csv",
            str(out / OUTPUTS[1]),
            "--html",
            str(out / OUTPUTS[3]),
            "--pairings",
            str(out / OUTPUTS[4]),
        ],
        cwd=work,
    )
    info = run_cli(["info", str(log), "--rig", str(rig)], cwd=work) if with_info else None
    problems = check(audit, info, out, lidar_topic=_lidar_topic(rig))
    if _cut_past_header(mutant, log) and audit.exit_code == 2:
        problems.append(("truncation-unread", f"a cut log is not read up to the cut: {what}"))
    if (_digest(log), _digest(rig)) != before:
        problems.append(("input-changed", "the log or rig changed"))
    left = sorted(p.name for p in work.iterdir() if p.name not in (log.name, rig.name, "out"))
    if left:
        problems.append(("leftovers", f"files beside the input: {left}"))
    return Outcome(mutant.id, what, audit, info, problems)


def _cut_past_header(mutant: Mutant, log: Path) -> bool:
    """A ROS 1 bag or .db3 cut after its first 4 KiB: should be read up to the cut (item 14).

    (An MCAP cut inside its header record, or any log cut before its first page, holds
    nothing readable: exit 2 is right there.)
    """
    if not mutant.mutator.startswith("truncate") or base_kind(mutant.base) == "mcap":
        return False
    data = mu.db3_file(log) if log.is_dir() else log
    return data.stat().st_size > 4096


def _lidar_topic(rig: Path) -> str | None:
    """The LiDAR topic a (possibly mutated) rig names, if it can be read at all."""
    import yaml

    try:
        doc = yaml.safe_load(rig.read_bytes())
        return str(doc["lidar"]["topic"])
    except Exception:
        return None


def check(
    audit: Run, info: Run | None, out: Path, *, lidar_topic: str | None = None
) -> list[tuple[str, str]]:
    """Every rule a run must keep, as (problem, detail).

    `info` must fail where `audit` found the LiDAR damaged (its error names the topic);
    damage `info` never reads (camera messages) is not asked of it.
    """
    problems: list[tuple[str, str]] = []
    for run in (audit, info):
        if run is None:
            continue
        verb = run.argv[0]
        if run.exit_code is None:
            problems.append(("timeout", f"{verb}: over {TIMEOUT_S:.0f} s"))
            continue
        if run.exit_code == 70:
            problems.append(("exit-70", f"{verb}: {_first_line(run.stderr)}"))
        elif run.exit_code not in DOCUMENTED_EXITS:
            problems.append(
                ("bad-exit", f"{verb}: exit {run.exit_code}: {_first_line(run.stderr)}")
            )
        if "Traceback" in run.stderr:
            problems.append(("traceback", f"{verb}: traceback on stderr"))
        errors = [ln for ln in run.stderr.splitlines() if ln.strip()]
        if run.exit_code not in (0, None) and (
            len(errors) != 1 or not errors[0].startswith(("error:", "internal error:"))
        ):
            problems.append(("not-one-line", f"{verb}: {len(errors)} stderr lines"))
        if run.max_rss_mb > MAX_RSS_MB:
            problems.append(("memory", f"{verb}: {run.max_rss_mb:.0f} MB"))
        if run.orphans:
            problems.append(("orphans", f"{verb}: processes left alive {run.orphans}"))
    written = sorted(p.name for p in out.iterdir())
    if audit.exit_code != 0 and written:
        problems.append(("partial-outputs", f"failed audit left {written}"))
    elif audit.exit_code == 0 and set(written) - set(OUTPUTS):
        problems.append(("temporaries", f"extra files {sorted(set(written) - set(OUTPUTS))}"))
    if (
        info is not None
        and audit.exit_code in (3, 4, 5)
        and info.exit_code == 0
        and lidar_topic is not None
        and lidar_topic in _first_line(audit.stderr)
    ):
        problems.append(
            (
                "info-disagrees",
                f"audit exit {audit.exit_code} ({_first_line(audit.stderr)}), info exit 0",
            )
        )
    return problems


def _first_line(text: str) -> str:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    return lines[0][:300] if lines else ""


# ---- known open causes ---------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class OpenCause:
    """A problem whose fix is another engineer's item of issue 10 (not merged here yet)."""

    key: str
    item: int
    owner: str
    matches: Callable[[Mutant, str, str, str], bool]
    """(mutant, problem, detail, description) -> True where this cause explains it."""


KNOWN_OPEN: tuple[OpenCause, ...] = ()
"""Causes found by the campaign and not yet fixed, each with its issue-10 item and owner.
Empty since the merge of every engineer's fixes (mcap chunk sizes and log times: mcapio;
rig bytes/values and atomic outputs: cli; info/audit agreement: fuzz; truncated bags:
bagio): a mutant hitting any of them again fails the suite."""


def classify(mutant: Mutant, outcome: Outcome) -> list[tuple[str, str, str | None]]:
    """Each problem as (problem, detail, known open cause key or None)."""
    out: list[tuple[str, str, str | None]] = []
    for problem, detail in outcome.problems:
        cause = next(
            (c.key for c in KNOWN_OPEN if c.matches(mutant, problem, detail, outcome.description)),
            None,
        )
        out.append((problem, detail, cause))
    return out


def run_campaign(
    mutants: list[Mutant],
    root: Path,
    *,
    jobs: int = 2,
    info_every: int = 1,
    on_done: Callable[[Mutant, Outcome], None] | None = None,
) -> dict[str, Outcome]:
    """Run every mutant (`jobs` at a time); each in `root/<id>`, removed when it passes."""
    cache = root / "_bases"
    cache.mkdir(parents=True, exist_ok=True)
    for base in BASES:  # simulate the bases once, before the threads start
        base_paths(base, cache)

    def one(index_mutant: tuple[int, Mutant]) -> tuple[Mutant, Outcome]:
        index, mutant = index_mutant
        work = root / mutant.id
        if work.exists():
            shutil.rmtree(work)
        outcome = run_mutant(mutant, cache, work, with_info=index % info_every == 0)
        if not outcome.problems:
            shutil.rmtree(work, ignore_errors=True)
        if on_done is not None:
            on_done(mutant, outcome)
        return mutant, outcome

    with ThreadPoolExecutor(max_workers=jobs) as pool:
        return {m.id: o for m, o in pool.map(one, enumerate(mutants))}


def save_failure(outcome: Outcome, mutant: Mutant, directory: Path) -> Path:
    """Write a failing mutant's replay record (seed, mutation, runs) as JSON."""
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{outcome.mutant}.json"
    record = {
        "replay": f"python benchmarks/fuzz_campaign.py --replay {mutant.id}",
        "base": mutant.base,
        "mutator": mutant.mutator,
        "seed": mutant.seed,
        "problems": [list(p) for p in classify(mutant, outcome)],
        **outcome.to_json(),
    }
    path.write_text(json.dumps(record, indent=2))
    return path
