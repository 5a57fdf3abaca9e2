#!/usr/bin/env python
"""Benchmark of `syncaudit audit` on a large realistic log (issue 5); prints its figures.

What it does, in one run:

1. Generates (once, cached in `--cache-dir`) a simulated drive log of at least `--size-gb`
   with a VLS-128 (real-format VelodyneScan packets), six cameras with JPEG-sized
   CompressedImage payloads, exposure metadata and trigger records, plus a log twice as
   long; each with its ground truth and rig file.
2. Creates (once) its own virtual environment with the peers `rosbag-doctor` and
   `clockdoctor`, never touching the project's environment.
3. Warms the page cache by reading the file, then runs each contender as a subprocess,
   in `--repeat` interleaved rounds (each figure is the contender's median-wall run), and
   measures wall time, CPU time (user + sys, reaped children included, from
   `os.wait4`) and the peak memory of the whole process tree (sampled from /proc every
   20 ms: the sum over processes of RSS and of PSS):
   the audit, the bare-mcap floor, the all-cores decompression limit and the peers; then
   the audit and the floor again on the 2x log (their difference is the cost per GB).
4. Prints a table, the ratios, the throughput and one verdict line per target. Nothing
   printed is hard-coded: every figure is measured in that run.

Run `python benchmarks/bench_audit.py --help`; see benchmarks/README.md for the figures.
Only the standard library and `mcap`/`yaml` are imported here at top level, so that the
contender subprocesses it starts are measured on their own.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import datetime as dt
import fcntl
import hashlib
import json
import os
import platform
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
DEFAULT_CACHE = REPO / "benchmarks" / ".cache"
GENERATOR_VERSION = 1
"""Bump when the generated log changes: cached logs carry it in their names."""
QUICK_GB = 0.2
PEERS: dict[str, str] = {"rosbag-doctor": "0.1.1", "clockdoctor": "0.1.0"}
SAMPLE_S = 0.02
CALIBRATION_S = 2.0
SIZE_MARGIN = 1.015
"""Duration margin over the calibrated estimate so the log is at least the asked size."""
TARGET_RSS_MB = 300.0
TARGET_RSS_GROWTH = 0.10
TARGET_LIMIT_RATIO = 1.5
DEFAULT_REPEAT = 5
MB = 1e6

# The simulated rig: a VLS-128 on the roof and six cameras all around, 60 deg apart.
LIDAR_MODEL = "VLS-128"
IMAGE_BYTES = 350_000
"""Per-frame CompressedImage payload: a 1920x1080 JPEG at usual quality is 250-400 KB."""
CAMERAS: tuple[tuple[str, float, float], ...] = (
    ("front", 0.0, 0.0),
    ("front_left", 60.0, 800.0),
    ("rear_left", 120.0, 0.0),
    ("rear", 180.0, -1_200.0),
    ("rear_right", 240.0, 0.0),
    ("front_right", 300.0, 0.0),
)
"""(name, yaw deg counter-clockwise from +X, applied-delay error us)."""
ZERO_AZIMUTH_DEG = 305.0
"""Trigger azimuth 55 deg before the front camera (packet azimuth 0): every camera's
theta is 55 deg or more, so each trigger delay is positive even in the tunnel's 12 ms
exposures (with 60 deg spacing one camera would otherwise sit on the trigger)."""
SEED = 5

FLOOR_CODE = """\
import sys
from mcap.reader import make_reader

files, topics = sys.argv[1].split(","), sys.argv[2:]
count = 0
for path in files:
    with open(path, "rb") as f:
        for _ in make_reader(f).iter_messages(topics=topics):
            count += 1
print(count)
"""
"""The floor for a Python tool: bare mcap iteration over the audit's topics, nothing done
per message (counting them only proves they were all read); a bag folder's MCAP files
(comma-separated) in turn."""

MCAP_LIMIT = """\
import multiprocessing
import os
import sys

import lz4.frame
import zstandard
from mcap.reader import make_reader


def work(job):
    # Each chunk read (preadv) into one reused buffer and decompressed into another: no
    # allocation, mapping or unmapping per chunk (the fastest way we know, ~15 % less CPU
    # than mapping each chunk; syncaudit's ChunkReader does the same). An uncompressed
    # chunk is read into the buffer: every byte of it is brought in.
    path, spans = job
    dctx = zstandard.ZstdDecompressor()
    out = bytearray(max(u for _, _, _, u in spans))
    buf = bytearray(max(s for _, s, _, _ in spans))
    total = 0
    with open(path, "rb") as f:
        for offset, size, compression, uncompressed in spans:
            data = memoryview(buf)[:size]
            assert os.preadv(f.fileno(), [data], offset) == size
            if compression == "zstd":
                reader = dctx.stream_reader(data, read_across_frames=False, closefd=False)
                got = reader.readinto(memoryview(out)[:uncompressed])
                reader.close()
                del reader
            elif compression == "lz4":
                got = len(lz4.frame.decompress(data))
            elif compression:
                raise ValueError(compression)
            else:
                got = len(data)
            data.release()
            total += got
    return total


if __name__ == "__main__":
    files, workers = sys.argv[1].split(","), os.cpu_count() or 1
    jobs, chunks = [], []
    for path in files:
        with open(path, "rb") as f:
            indexes = make_reader(f).get_summary().chunk_indexes
        # A chunk's records are the last field of its record: they end where the chunk ends.
        spans = [
            (c.chunk_start_offset + c.chunk_length - c.compressed_size, c.compressed_size,
             c.compression, c.uncompressed_size)
            for c in indexes
        ]
        size = max(1, len(spans) // (8 * workers))
        jobs += [(path, spans[i : i + size]) for i in range(0, len(spans), size)]
        chunks += indexes
    with multiprocessing.get_context("fork").Pool(workers) as pool:
        total = sum(pool.imap_unordered(work, jobs))
    expected = sum(c.uncompressed_size for c in chunks)
    assert total == expected, (total, expected)
    print(len(chunks), total, workers)
"""
"""The machine's limit for MCAP files (a bare `.mcap`, or a bag folder's comma-separated
files): every chunk read and decompressed (as recorded) by a pool of all cores, nothing
else."""


# ================================================================================ helpers


def _log(text: str = "") -> None:
    print(text, flush=True)


def _gb(nbytes: float) -> str:
    return f"{nbytes / 1e9:.2f} GB"


@contextlib.contextmanager
def _cache_lock(cache: Path) -> Iterator[None]:
    """One benchmark per cache directory at a time (stale temporaries are then safe to drop)."""
    cache.mkdir(parents=True, exist_ok=True)
    with (cache / ".bench.lock").open("w") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise SystemExit(f"another benchmark holds {cache}/.bench.lock") from None
        yield


def _drop_stale_temporaries(cache: Path) -> None:
    """Remove temporaries an interrupted run left (the writers' hidden `.*.tmp` outputs)."""
    for entry in cache.glob(".*.tmp"):
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)


def _write_json_atomic(path: Path, payload: dict[str, Any]) -> None:
    """Write JSON beside `path` under a temporary name, then rename it into place."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)  # as open() would have created it
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            json.dump(payload, handle, indent=1)
            handle.write("\n")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _git_rev() -> str:
    """Short commit of the working tree (+ '-dirty'), so a result names what it measured."""
    try:
        rev = subprocess.run(
            ["git", "-C", str(REPO), "describe", "--always", "--dirty"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return rev


def _memory_gib() -> float:
    with contextlib.suppress(OSError, ValueError, IndexError):
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                return int(line.split()[1]) / 1024**2
    return float("nan")


# ============================================================================ measurement


def _children(pid: int) -> list[int]:
    """Direct children of `pid` (children of any of its threads), from /proc."""
    out: list[int] = []
    with contextlib.suppress(OSError):
        for task in os.listdir(f"/proc/{pid}/task"):
            with contextlib.suppress(OSError), open(f"/proc/{pid}/task/{task}/children") as f:
                out.extend(int(v) for v in f.read().split())
    return out


def _memory_kb(pid: int) -> tuple[int, int]:
    """(RSS, PSS) of one process in KiB; (0, 0) once it is gone."""
    try:
        with open(f"/proc/{pid}/smaps_rollup") as f:
            text = f.read()
    except OSError:
        return 0, 0
    rss = pss = 0
    for line in text.splitlines():
        if line.startswith("Rss:"):
            rss = int(line.split()[1])
        elif line.startswith("Pss:"):
            pss = int(line.split()[1])
    return rss, pss


class TreeSampler(threading.Thread):
    """Samples the memory of a process and all its descendants every `interval` seconds.

    Keeps the peak over time of the tree's summed RSS and summed PSS (PSS splits pages
    shared between forked workers among them, so its sum is the tree's real footprint;
    the RSS sum counts shared pages once per process) and the most processes seen.
    """

    def __init__(self, root: int, interval: float = SAMPLE_S) -> None:
        super().__init__(daemon=True)
        self.root = root
        self.interval = interval
        self.peak_rss_kb = 0
        self.peak_pss_kb = 0
        self.peak_largest_kb = 0
        """Peak RSS of the largest single process (the parent or one worker)."""
        self.max_procs = 0
        self.samples = 0
        self._stop_event = threading.Event()

    def run(self) -> None:
        while not self._stop_event.is_set():
            self.sample()
            self._stop_event.wait(self.interval)

    def sample(self) -> None:
        """One look at the tree."""
        pids, todo = [], [self.root]
        while todo:
            pid = todo.pop()
            pids.append(pid)
            todo.extend(_children(pid))
        rss = pss = alive = 0
        for pid in pids:
            r, p = _memory_kb(pid)
            rss += r
            pss += p
            alive += r > 0
            self.peak_largest_kb = max(self.peak_largest_kb, r)
        self.peak_rss_kb = max(self.peak_rss_kb, rss)
        self.peak_pss_kb = max(self.peak_pss_kb, pss)
        self.max_procs = max(self.max_procs, alive)
        self.samples += 1

    def stop(self) -> None:
        self._stop_event.set()
        self.join()


def _machine_busy_s() -> float:
    """CPU seconds the whole machine has spent busy since boot (all cores, /proc/stat)."""
    with open("/proc/stat") as f:
        fields = [int(v) for v in f.readline().split()[1:]]
    user, nice, system, _idle, _iowait, irq, softirq, steal = (fields + [0] * 8)[:8]
    return (user + nice + system + irq + softirq + steal) / os.sysconf("SC_CLK_TCK")


@dataclasses.dataclass(slots=True)
class Run:
    """One measured subprocess."""

    name: str
    argv: list[str]
    wall_s: float = float("nan")
    cpu_s: float = float("nan")
    rss_mb: float = float("nan")
    """Peak over time of the tree's summed RSS (at least the largest process's ru_maxrss)."""
    pss_mb: float = float("nan")
    """Peak over time of the tree's summed PSS (at most the RSS figure)."""
    largest_mb: float = float("nan")
    """Peak RSS of the largest single process (at least its ru_maxrss)."""
    procs: int = 0
    returncode: int | None = None
    timed_out: bool = False
    other_cpu_s: float = float("nan")
    """CPU time the rest of the machine used meanwhile (others' work competing for cores)."""
    warm_gbps: float = float("nan")
    """Speed of the page-cache warm-up read of its log just before it ran."""
    stdout: str = ""
    stderr: str = ""

    @property
    def ok(self) -> bool:
        return self.returncode == 0 and not self.timed_out

    def error_line(self) -> str:
        """The last meaningful line the process printed on failure."""
        if self.timed_out:
            return f"timed out after {self.wall_s:.0f} s (killed)"
        lines = [ln.strip() for ln in (self.stderr + "\n" + self.stdout).splitlines()]
        lines = [ln for ln in lines if ln]
        return f"exit {self.returncode}: {lines[-1] if lines else '(no output)'}"[:300]


def measure(
    name: str,
    argv: Sequence[str],
    scratch: Path,
    timeout_s: float,
    cwd: Path | None = None,
    warm: Path | None = None,
    env: dict[str, str] | None = None,
) -> Run:
    """Run `argv` once, with stdout/stderr to files in `scratch`, and measure it; read
    `warm` first so that the run finds its log in the page cache."""
    run = Run(name, list(argv))
    if warm is not None:
        run.warm_gbps = warm_page_cache(warm)
    slug = "".join(c if c.isalnum() else "_" for c in name)
    out_path, err_path = scratch / f"{slug}.stdout", scratch / f"{slug}.stderr"
    with out_path.open("wb") as out, err_path.open("wb") as err:
        busy_before = _machine_busy_s()
        start = time.perf_counter()
        proc = subprocess.Popen(
            run.argv, stdout=out, stderr=err, cwd=cwd or scratch, start_new_session=True, env=env
        )
        sampler = TreeSampler(proc.pid)
        sampler.start()

        def kill() -> None:
            run.timed_out = True
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)

        timer = threading.Timer(timeout_s, kill)
        timer.start()
        try:
            _, status, usage = os.wait4(proc.pid, 0)
        finally:
            timer.cancel()
        run.wall_s = time.perf_counter() - start
        busy = _machine_busy_s() - busy_before
        sampler.stop()
        proc.returncode = run.returncode = os.waitstatus_to_exitcode(status)
    if run.timed_out:
        # Workers of a killed contender are in its session: take them down too.
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
    run.cpu_s = usage.ru_utime + usage.ru_stime
    run.other_cpu_s = max(0.0, busy - run.cpu_s)
    run.rss_mb = max(sampler.peak_rss_kb, usage.ru_maxrss) * 1024 / MB
    run.pss_mb = sampler.peak_pss_kb * 1024 / MB if sampler.peak_pss_kb else run.rss_mb
    run.largest_mb = max(sampler.peak_largest_kb, usage.ru_maxrss) * 1024 / MB
    run.procs = max(sampler.max_procs, 1)
    run.stdout = out_path.read_text(errors="replace")[-20_000:]
    run.stderr = err_path.read_text(errors="replace")[-20_000:]
    return run


def warm_bytecode(*also: Path) -> str:
    """Compile syncaudit's bytecode up front, so the first contender run does not pay for
    recompiling sources edited since the last import (the peers' venv is compiled by pip).

    `also`: other source trees run here (a `--baseline-src`): without their bytecode every
    run of theirs compiles every module (~0.07 CPU s) where `PYTHONDONTWRITEBYTECODE` is set.
    """
    import importlib.util

    spec = importlib.util.find_spec("syncaudit")
    if spec is None or not spec.submodule_search_locations:
        return "syncaudit not importable"
    where = [*spec.submodule_search_locations, *map(str, also)]
    done = subprocess.run([sys.executable, "-m", "compileall", "-q", *where], check=False)
    return "compiled" if done.returncode == 0 else f"compileall exit {done.returncode}"


def warm_page_cache(path: Path) -> float:
    """Read the whole file once (so every contender finds it in the page cache); GB/s."""
    start = time.perf_counter()
    total = 0
    with path.open("rb", buffering=0) as f:
        while block := f.read(16 * 1024 * 1024):
            total += len(block)
    return total / 1e9 / (time.perf_counter() - start)


# ============================================================================== the logs


def sim_config(duration_s: float) -> dict[str, Any]:
    """The simulator configuration of the benchmark log (JSON form of SyncSimConfig)."""
    return {
        "seed": SEED,
        "duration_s": duration_s,
        "log_format": "mcap",
        "overwrite": True,
        "lidar_model": LIDAR_MODEL,
        "lidar_returns": "random",
        "zero_azimuth_deg": ZERO_AZIMUTH_DEG,
        "image_kind": "compressed",
        "image_bytes": IMAGE_BYTES,
        "cameras": [
            {"name": name, "yaw_deg": yaw, "delay_error_us": error} for name, yaw, error in CAMERAS
        ],
    }


def generate(out: Path, duration_s: float) -> None:
    """Simulate the log, its truth and its rig file (runs in a measured subprocess)."""
    import yaml

    from syncaudit.simulate.rig_file import rig_from_truth
    from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log
    from syncaudit.writers.atomic import write_text_atomic
    from syncaudit.writers.provenance import COMMENT_MARK

    truth = simulate_sync_log(out, SyncSimConfig.model_validate(sim_config(duration_s)))
    rig = rig_from_truth(truth).model_dump(mode="json", exclude_defaults=True)
    write_text_atomic(rig_path(out), COMMENT_MARK + yaml.safe_dump(rig, sort_keys=False))


def rig_path(log: Path) -> Path:
    return log.with_name(log.name + ".rig.yaml")


def meta_path(log: Path) -> Path:
    return log.with_name(log.name + ".bench.json")


def _config_key() -> str:
    """Short hash of everything that shapes the log but its length."""
    payload = json.dumps([GENERATOR_VERSION, sim_config(0.0)], sort_keys=True)
    return hashlib.sha256(payload.encode()).hexdigest()[:10]


def _generate_measured(out: Path, duration_s: float, scratch: Path, timeout_s: float) -> Run:
    argv = [
        sys.executable,
        str(Path(__file__).resolve()),
        "--generate-to",
        str(out),
        "--duration-s",
        repr(duration_s),
    ]
    run = measure(f"generate {out.name}", argv, scratch, timeout_s, cwd=REPO)
    if not run.ok:
        raise SystemExit(f"generating {out} failed: {run.error_line()}")
    return run


def calibrate_rate(cache: Path, scratch: Path, timeout_s: float) -> float:
    """Bytes of log per second of simulated time, from a short simulation."""
    with tempfile.TemporaryDirectory(prefix=".calibrate.", suffix=".tmp", dir=cache) as tmp:
        out = Path(tmp) / "calibrate.mcap"
        _generate_measured(out, CALIBRATION_S, scratch, timeout_s)
        return out.stat().st_size / CALIBRATION_S


def ensure_log(
    cache: Path, name: str, duration_s: float, scratch: Path, timeout_s: float
) -> dict[str, Any]:
    """The cached log `name` (generated if absent) and its metadata; the metadata file is
    written last, so a log without it is incomplete and is generated again."""
    log = cache / name
    meta_file = meta_path(log)
    if meta_file.exists() and log.exists() and rig_path(log).exists():
        meta: dict[str, Any] = json.loads(meta_file.read_text())
        meta["cached"] = True
        return meta
    _log(f"generating {log.name} ({duration_s:.1f} s of log) ...")
    run = _generate_measured(log, duration_s, scratch, timeout_s)
    meta = {
        "log": str(log),
        "duration_s": duration_s,
        "size_bytes": log.stat().st_size,
        "generated_at": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "generator_version": GENERATOR_VERSION,
        "generation": {"wall_s": run.wall_s, "cpu_s": run.cpu_s, "peak_rss_mb": run.rss_mb},
        "config": sim_config(duration_s),
    }
    _write_json_atomic(meta_file, meta)
    meta["cached"] = False
    return meta


def _log_name(size_gb: float, multiple: int) -> str:
    return f"bench_{size_gb:g}gb_x{multiple}_{_config_key()}.mcap"


def prepare_logs(
    cache: Path, size_gb: float, scratch: Path, timeout_s: float, *, two_needed: bool = True
) -> tuple[dict[str, Any], dict[str, Any] | None]:
    """The 1x log (at least `size_gb`) and the 2x log (twice its duration; None where not
    `two_needed`, so a 1x-only run generates no 4 GB log)."""
    one_name = _log_name(size_gb, 1)
    if meta_path(cache / one_name).exists():
        duration = float(json.loads(meta_path(cache / one_name).read_text())["duration_s"])
    else:
        rate = calibrate_rate(cache, scratch, timeout_s)
        duration = round(size_gb * 1e9 / rate * SIZE_MARGIN, 1)
    one = ensure_log(cache, one_name, duration, scratch, timeout_s)
    if not two_needed:
        return one, None
    two = ensure_log(cache, _log_name(size_gb, 2), 2 * one["duration_s"], scratch, timeout_s)
    return one, two


@dataclasses.dataclass(frozen=True, slots=True)
class LogFacts:
    """What the benchmark needs to know about one log."""

    path: Path
    size_bytes: int
    messages: int
    audit_topics: list[str]
    audit_messages: int
    chunks: int
    compression: str
    uncompressed_bytes: int


def rig_topics(rig_file: Path) -> list[str]:
    """The audit's topics by the rig file: the LiDAR's and each camera's image, exposure and
    trigger topics, and /tf_static where a camera names a frame."""
    import yaml

    rig = yaml.safe_load(rig_file.read_text())
    topics = [rig["lidar"]["topic"]]
    for cam in rig.get("cameras", []):
        topics += [cam[k] for k in ("image_topic", "exposure_topic", "trigger_topic") if cam.get(k)]
    if any(cam.get("frame_id") for cam in rig.get("cameras", [])):
        topics.append("/tf_static")
    return topics


def log_facts(path: Path) -> LogFacts:
    """Counts from the MCAP summary and the audit's topics from the rig file."""
    from mcap.reader import make_reader

    topics = rig_topics(rig_path(path))
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    if summary is None or summary.statistics is None:
        raise SystemExit(f"{path}: no MCAP summary/statistics")
    by_topic: dict[str, int] = {}
    for channel_id, count in summary.statistics.channel_message_counts.items():
        topic = summary.channels[channel_id].topic
        by_topic[topic] = by_topic.get(topic, 0) + count
    chunks = summary.chunk_indexes
    return LogFacts(
        path=path,
        size_bytes=path.stat().st_size,
        messages=summary.statistics.message_count,
        audit_topics=topics,
        audit_messages=sum(by_topic.get(t, 0) for t in topics),
        chunks=len(chunks),
        compression="/".join(sorted({c.compression or "none" for c in chunks})),
        uncompressed_bytes=sum(c.uncompressed_size for c in chunks),
    )


# ================================================================================== peers


def ensure_peers(cache: Path, scratch: Path) -> tuple[Path | None, str]:
    """The peers' own virtual environment (created once); (bin dir or None, note)."""
    venv = cache / "peers-venv"
    marker = venv / ".bench-complete"
    wanted = json.dumps(PEERS, sort_keys=True)
    if marker.exists() and marker.read_text() == wanted:
        return venv / "bin", "cached"
    shutil.rmtree(venv, ignore_errors=True)
    _log(f"creating {venv} with " + ", ".join(f"{k}=={v}" for k, v in PEERS.items()) + " ...")
    log_file = scratch / "peers-install.log"
    with log_file.open("w") as out:
        steps = [
            [sys.executable, "-m", "venv", str(venv)],
            [str(venv / "bin" / "python"), "-m", "pip", "install", "--quiet"]
            + [f"{k}=={v}" for k, v in PEERS.items()],
        ]
        for step in steps:
            if subprocess.run(step, stdout=out, stderr=subprocess.STDOUT).returncode != 0:
                shutil.rmtree(venv, ignore_errors=True)
                tail = log_file.read_text(errors="replace").strip().splitlines()[-1:]
                return None, f"installing the peers failed: {' '.join(tail)}"
    marker.write_text(wanted)
    return venv / "bin", "installed now"


def peer_runs(bin_dir: Path, log: Path, scratch: Path, timeout_s: float) -> list[Run]:
    """Each peer once on the log, with the invocation that analyses the whole file's timing.

    Both run on a symlink to the log inside `scratch`: clockdoctor writes its decoded-message
    JSONL beside its input whatever `--out-dir` says, and must not litter the cache.
    """
    link = scratch / log.name
    link.unlink(missing_ok=True)
    link.symlink_to(log)
    runs = [
        measure(
            "rosbag-doctor",
            [str(bin_dir / "rosbag-doctor"), str(link), "--format", "json"],
            scratch,
            timeout_s,
            warm=log,
        ),
        measure(
            "clockdoctor",
            [str(bin_dir / "clockdoctor"), str(link), "--out-dir", str(scratch / "clockdoctor")],
            scratch,
            timeout_s,
            warm=log,
        ),
    ]
    return runs


# ================================================================================ figures


def audit_argv(log: Path, json_out: Path) -> list[str]:
    """`syncaudit audit LOG --rig LOG.rig.yaml --json-out F --overwrite`.

    The JSON goes to a scratch file, not /dev/null: the atomic writer renames a temporary
    onto its target, which (run as root) would replace /dev/null by a regular file.
    `--overwrite`: every round after the first writes onto the previous round's file, which
    the CLI refuses (exit 8) without it.
    """
    exe = Path(sys.executable).with_name("syncaudit")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "syncaudit.cli"]
    return [
        *cmd,
        "audit",
        str(log),
        "--rig",
        str(rig_path(log)),
        "--json-out",
        str(json_out),
        "--overwrite",
    ]


def audit_vs_truth(json_out: Path, log: Path) -> str:
    """One line: does the audit still find the simulated truth (Eq. 5 per camera)?"""
    try:
        result = json.loads(json_out.read_text())
        truth = json.loads(Path(str(log) + ".truth.json").read_text())
    except (OSError, ValueError) as exc:
        return f"audit output not checked: {exc}"
    worst, paired, total = 0.0, 0, 0
    for cam in result.get("cameras", []):
        t = truth["cameras"].get(cam.get("camera"))
        if t is None or cam.get("error_mean_us") is None:
            return f"audit output not checked: camera {cam.get('camera')} not comparable"
        worst = max(worst, abs(cam["error_mean_us"] - t["error_mean_ns"] / 1e3))
        paired += int(cam.get("frames_paired", 0))
        total += len(t["frames"])
    n = len(result.get("cameras", []))
    return (
        f"audit vs truth: {n}/{len(truth['cameras'])} cameras, {paired}/{total} frames paired, "
        f"max |Eq. 5 error mean - truth| = {worst:.1f} us"
    )


def median_run(runs: list[Run]) -> Run:
    """The run with the median wall time (the lower middle of an even count; a failed run,
    if any, so that failures show)."""
    failed = [run for run in runs if not run.ok]
    if failed:
        return failed[0]
    return sorted(runs, key=lambda run: run.wall_s)[(len(runs) - 1) // 2]


def marginal_cost(
    audit: Run, audit2: Run, floor: Run, floor2: Run, one: LogFacts, two: LogFacts
) -> str:
    """Seconds per extra GB (2x minus 1x) and the fixed start-up/tail cost they imply:
    what decides the wall time on the tens-of-GB logs a fleet records."""
    if not all(run.ok for run in (audit, audit2, floor, floor2)):
        return "marginal cost: no data (a run failed)"
    extra_gb = (two.size_bytes - one.size_bytes) / 1e9
    audit_rate = (audit2.wall_s - audit.wall_s) / extra_gb
    floor_rate = (floor2.wall_s - floor.wall_s) / extra_gb
    fixed = audit.wall_s - audit_rate * one.size_bytes / 1e9
    return (
        f"marginal cost per extra GB (2x - 1x): audit {audit_rate:.2f} s/GB, floor "
        f"{floor_rate:.2f} s/GB (x{audit_rate / floor_rate:.2f}); audit fixed cost "
        f"(start-up, pool, analysis, report) ~{fixed:.2f} s"
    )


def _fmt(value: float, digits: int = 1) -> str:
    return "-" if value != value else f"{value:,.{digits}f}"


def table(rows: list[tuple[Run, LogFacts]]) -> str:
    """The contenders side by side."""
    head = (
        f"{'contender':<28}{'wall s':>9}{'CPU s':>9}{'CPU/wall':>9}{'RSS MB':>9}{'PSS MB':>9}"
        f"{'procs':>6}{'MB/s':>9}{'msg/s':>11}{'others':>8}  result"
    )
    lines = [head, "-" * len(head)]
    for run, facts in rows:
        ok = run.ok
        lines.append(
            f"{run.name:<28}{_fmt(run.wall_s, 2):>9}{_fmt(run.cpu_s, 2):>9}"
            f"{_fmt(run.cpu_s / run.wall_s, 2):>9}{_fmt(run.rss_mb, 0):>9}{_fmt(run.pss_mb, 0):>9}"
            f"{run.procs:>6}{_fmt(facts.size_bytes / MB / run.wall_s, 0) if ok else '-':>9}"
            f"{_fmt(facts.audit_messages / run.wall_s, 0) if ok else '-':>11}"
            f"{_fmt(run.other_cpu_s / run.wall_s, 2):>8}  {'ok' if ok else 'FAILED'}"
        )
    return "\n".join(lines)


def _mark(met: bool) -> str:
    return "[met]    " if met else "[NOT MET]"


def verdicts(
    audit: Run, floor: Run, limit: Run, audit2: Run | None, peers: list[Run], peer_note: str
) -> list[str]:
    """One line per target of the issue."""
    out = []
    if not audit.ok:
        return [f"[NOT MET] every target: the audit failed ({audit.error_line()})"]
    if floor.ok:
        out.append(
            f"{_mark(audit.wall_s <= floor.wall_s)} audit wall <= bare-mcap floor: "
            f"{audit.wall_s:.2f} s vs {floor.wall_s:.2f} s (x{audit.wall_s / floor.wall_s:.2f})"
        )
    else:
        out.append(f"[no data] audit vs floor: the floor failed ({floor.error_line()})")
    if limit.ok:
        ratio = audit.wall_s / limit.wall_s
        out.append(
            f"{_mark(ratio <= TARGET_LIMIT_RATIO)} audit wall <= {TARGET_LIMIT_RATIO}x all-cores "
            f"limit: {audit.wall_s:.2f} s vs {limit.wall_s:.2f} s (x{ratio:.2f})"
        )
    else:
        out.append(f"[no data] audit vs limit: the limit failed ({limit.error_line()})")
    peaks = [audit.pss_mb] + ([audit2.pss_mb] if audit2 is not None and audit2.ok else [])
    out.append(
        f"{_mark(max(peaks) < TARGET_RSS_MB)} audit peak memory < {TARGET_RSS_MB:.0f} MB: "
        + ", ".join(f"{p:.0f} MB" for p in peaks)
        + " (1x"
        + (", 2x" if len(peaks) > 1 else "")
        + "; tree PSS sum)"
    )
    if audit2 is not None and audit2.ok:
        growth = audit2.pss_mb / audit.pss_mb - 1.0
        out.append(
            f"{_mark(growth < TARGET_RSS_GROWTH)} flat memory, 2x log adds < "
            f"{TARGET_RSS_GROWTH:.0%}: {audit.pss_mb:.0f} -> {audit2.pss_mb:.0f} MB "
            f"({growth:+.1%})"
        )
    elif audit2 is not None:
        out.append(f"[NOT MET] flat memory: the audit failed on the 2x log ({audit2.error_line()})")
    if not peers:
        out.append(f"[no data] faster than both peers: {peer_note}")
    for peer in peers:
        if peer.ok:
            out.append(
                f"{_mark(audit.wall_s < peer.wall_s)} faster than {peer.name}: "
                f"{audit.wall_s:.2f} s vs {peer.wall_s:.2f} s (x{audit.wall_s / peer.wall_s:.2f})"
            )
        else:
            out.append(
                f"[no data] faster than {peer.name}: the peer failed on the log "
                f"after {peer.wall_s:.1f} s ({peer.error_line()})"
            )
    return out


def describe_log(label: str, meta: dict[str, Any], facts: LogFacts) -> str:
    gen = meta["generation"]
    how = f"cached, generated {meta['generated_at']}" if meta["cached"] else "generated now"
    return (
        f"{label}: {facts.path.name}  {_gb(facts.size_bytes)} on disk "
        f"({_gb(facts.uncompressed_bytes)} in {facts.chunks} {facts.compression} chunks), "
        f"{meta['duration_s']:.1f} s of log, {facts.messages:,} messages "
        f"({facts.audit_messages:,} on the audit's {len(facts.audit_topics)} topics)\n"
        f"    {how} in {gen['wall_s']:.1f} s wall, {gen['cpu_s']:.1f} s CPU, "
        f"generator peak RSS {gen['peak_rss_mb']:.0f} MB"
    )


# ============================================================================ containers
# The same 1x log in every container a recorder writes, each audited against its own
# floor (the fastest single-process read of the audit's messages with the container's
# standard library) and its own 2-core limit (every byte of the audit's data read, and
# decompressed where compressed, by a pool of all cores, nothing else).

CONTAINERS: tuple[str, ...] = (
    "mcap",
    "ros2-mcap",
    "ros2-mcap-split",
    "ros2-sqlite",
    "ros1-lz4",
    "ros1-bz2",
)
SPLIT_PARTS = 4

SQLITE_FLOOR = """\
import sqlite3, sys

db, topics = sys.argv[1], sys.argv[2:]
con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
marks = ",".join("?" * len(topics))
ids = [r[0] for r in con.execute(f"SELECT id FROM topics WHERE name IN ({marks})", topics)]
marks = ",".join("?" * len(ids))
count = 0
for _ts, _data in con.execute(
    f"SELECT timestamp, data FROM messages WHERE topic_id IN ({marks}) ORDER BY timestamp", ids
):
    count += 1
print(count)
"""
"""Floor of a SQLite bag: sqlite3 selecting the audit's topics' rows in time order."""

SQLITE_LIMIT = """\
import multiprocessing, os, sqlite3, sys

def work(job):
    db, lo, hi, ids = job
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    marks = ",".join("?" * len(ids))
    total = 0
    for (data,) in con.execute(
        f"SELECT data FROM messages WHERE id >= ? AND id < ? AND topic_id IN ({marks})",
        [lo, hi, *ids],
    ):
        total += len(data)
    return total

if __name__ == "__main__":
    db, topics, workers = sys.argv[1], sys.argv[2:], os.cpu_count() or 1
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    marks = ",".join("?" * len(topics))
    ids = [r[0] for r in con.execute(f"SELECT id FROM topics WHERE name IN ({marks})", topics)]
    lo, hi = con.execute("SELECT min(id), max(id) FROM messages").fetchone()
    step = max(1, (hi - lo + 1) // (8 * workers))
    jobs = [(db, a, a + step, ids) for a in range(lo, hi + 1, step)]
    with multiprocessing.get_context("fork").Pool(workers) as pool:
        print(sum(pool.imap_unordered(work, jobs)))
"""

ROS1_FLOOR = """\
import sys
from pathlib import Path
from rosbags.rosbag1 import Reader

path, topics = sys.argv[1], set(sys.argv[2:])
count = 0
with Reader(Path(path)) as reader:
    conns = [c for c in reader.connections if c.topic in topics]
    for _conn, _t, _data in reader.messages(connections=conns):
        count += 1
print(count)
"""
"""Floor of a ROS 1 bag: rosbags' reader over the audit's topics (raw bytes, no decoding)."""

ROS1_LIMIT = """\
import bz2, multiprocessing, os, struct, sys
from pathlib import Path
import lz4.frame
from rosbags.rosbag1 import Reader

def fields(buf):
    out, pos = {}, 0
    while pos < len(buf):
        (n,) = struct.unpack_from("<I", buf, pos)
        key, _, value = bytes(buf[pos + 4:pos + 4 + n]).partition(b"=")
        out[key] = value
        pos += 4 + n
    return out

def work(job):
    path, positions = job
    total = 0
    with open(path, "rb") as f:
        for pos in positions:
            f.seek(pos)
            (hlen,) = struct.unpack("<I", f.read(4))
            head = fields(f.read(hlen))
            (dlen,) = struct.unpack("<I", f.read(4))
            data = f.read(dlen)
            kind = head[b"compression"]
            if kind == b"bz2":
                data = bz2.decompress(data)
            elif kind == b"lz4":
                data = lz4.frame.decompress(data)
            total += len(data)
    return total

if __name__ == "__main__":
    path, workers = sys.argv[1], os.cpu_count() or 1
    with Reader(Path(path)) as reader:
        positions = sorted(c.pos for c in reader.chunk_infos)
    size = max(1, len(positions) // (8 * workers))
    jobs = [(path, positions[i:i + size]) for i in range(0, len(positions), size)]
    with multiprocessing.get_context("fork").Pool(workers) as pool:
        print(sum(pool.imap_unordered(work, jobs)))
"""
"""ROS 1 limit: every chunk of the bag read and decompressed by a pool of all cores."""


def container_path(cache: Path, one: Path, kind: str) -> Path:
    """Where the 1x log converted to `kind` is cached (a file or a bag folder)."""
    stem = one.name.removesuffix(".mcap")
    return {
        "mcap": one,
        "ros2-mcap": cache / f"{stem}.ros2-mcap",
        "ros2-mcap-split": cache / f"{stem}.ros2-mcap-split",
        "ros2-sqlite": cache / f"{stem}.ros2-sqlite",
        "ros1-lz4": cache / f"{stem}.lz4.bag",
        "ros1-bz2": cache / f"{stem}.bz2.bag",
    }[kind]


def _write_rosbag2(src: Path, dst: Path, parts: int, storage: str, stem: str) -> None:
    """The bare MCAP's messages as a rosbag2 folder (rosbags' writer), split into `parts`
    files by time as rosbag2 does (each file declares its channels anew), named `stem_N`."""
    from syncaudit.logs.mcap.reader import McapLog
    from syncaudit.logs.typesys import TypeRegistry
    from syncaudit.writers.rosbag2_split import SplitBagWriter

    with McapLog(src) as log:
        start, end = log.summary.start_ns, log.summary.end_ns
        assert start is not None and end is not None
        registry = TypeRegistry(ros1=False, log_types=log.log_types("cdr"), eager=True)
        topics = [(name, info.msgtype) for name, info in log.topics.items()]
        bag = SplitBagWriter(dst, registry.store, storage=storage, stem=stem)
        stream = log.messages()
        pending = next(stream, None)
        for part in range(parts):
            hi = start + (end - start + 1) * (part + 1) // parts
            bag.start_part(topics)
            while pending is not None and pending.log_time_ns < hi:
                bag.write(pending.topic, pending.log_time_ns, bytes(pending.data))
                pending = next(stream, None)
        bag.close()


def convert_container(one: Path, kind: str, dst: Path) -> None:
    """Write the 1x log as `kind` at `dst` (runs in a measured subprocess), atomically."""
    tmp = dst.with_name(f".{dst.name}.tmp")
    if tmp.is_dir():
        shutil.rmtree(tmp)
    tmp.unlink(missing_ok=True)
    if kind in ("ros2-mcap", "ros2-mcap-split", "ros2-sqlite"):
        parts = SPLIT_PARTS if kind == "ros2-mcap-split" else 1
        storage = "sqlite" if kind == "ros2-sqlite" else "mcap"
        _write_rosbag2(one, tmp, parts, storage, dst.name)
    else:  # ROS 1: rosbags' own converter, from the SQLite bag
        from rosbags.convert import convert

        sqlite = container_path(one.parent, one, "ros2-sqlite")
        compress = kind.removeprefix("ros1-")
        tmp.mkdir()  # rosbags writes ROS 1 for a `.bag` suffix: the bag goes inside
        inner = tmp / dst.name
        convert([sqlite], inner, "sqlite3", 8, compress, "file", None, None, [], [], [], [])
        inner.rename(dst)
        tmp.rmdir()
        shutil.copyfile(rig_path(one), rig_path(dst))
        return
    tmp.rename(dst)
    shutil.copyfile(rig_path(one), rig_path(dst))


def ensure_containers(
    cache: Path, one: Path, scratch: Path, timeout_s: float, kinds: Sequence[str] = CONTAINERS
) -> dict[str, Path]:
    """Every container (of `kinds`) of the 1x log, converted once and cached."""
    out: dict[str, Path] = {}
    for kind in kinds:
        path = container_path(cache, one, kind)
        if not path.exists():
            _log(f"converting the 1x log to {kind} ...")
            argv = [
                sys.executable,
                str(Path(__file__).resolve()),
                "--convert-to",
                kind,
                "--convert-from",
                str(one),
                "--convert-dst",
                str(path),
            ]
            run = measure(f"convert {kind}", argv, scratch, timeout_s, cwd=REPO)
            if not run.ok:
                raise SystemExit(f"converting to {kind} failed: {run.error_line()}")
        out[kind] = path
    return out


def _storage_files(path: Path, suffix: str) -> list[Path]:
    import yaml

    meta = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    return [path / name for name in meta["relative_file_paths"] if name.endswith(suffix)]


def container_commands(kind: str, path: Path, topics: list[str]) -> tuple[list[str], list[str]]:
    """(floor argv, limit argv) for one container."""
    py = sys.executable
    if kind == "mcap":
        return [py, "-c", FLOOR_CODE, str(path), *topics], [py, "-c", MCAP_LIMIT, str(path)]
    if kind.startswith("ros2-mcap"):
        files = ",".join(str(p) for p in _storage_files(path, ".mcap"))
        return [py, "-c", FLOOR_CODE, files, *topics], [py, "-c", MCAP_LIMIT, files]
    if kind == "ros2-sqlite":
        (db,) = _storage_files(path, ".db3")
        return [py, "-c", SQLITE_FLOOR, str(db), *topics], [
            py,
            "-c",
            SQLITE_LIMIT,
            str(db),
            *topics,
        ]
    return [py, "-c", ROS1_FLOOR, str(path), *topics], [py, "-c", ROS1_LIMIT, str(path)]


def _disk_bytes(path: Path) -> int:
    if path.is_file():
        return path.stat().st_size
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def _warm_any(path: Path) -> float:
    """Warm the page cache for a file or every file of a folder; GB/s over all of them."""
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    start = time.perf_counter()
    for p in files:
        warm_page_cache(p)
    return _disk_bytes(path) / 1e9 / (time.perf_counter() - start) if files else float("nan")


@dataclasses.dataclass(slots=True)
class Figures:
    """The median runs of one container at one log size (this run's, or a stored one's)."""

    kind: str
    size: str
    """"1x" or "2x"."""
    disk_bytes: int
    runs: dict[str, Run]
    """"audit", "floor", "limit"."""
    same: str
    measured: str = "now"
    """"now", or when and at which load a stored run measured it."""

    def ok(self, name: str) -> bool:
        run = self.runs.get(name)
        return run is not None and run.ok

    def wall(self, name: str) -> float:
        return self.runs[name].wall_s if self.ok(name) else float("nan")


RESULTS_FILE = "container-results.json"
"""Each container's last figures per size, so a long container (bz2) can be measured one
size per run and still get its per-GB figures."""


def _store_figures(cache: Path, figures: list[Figures], load: float) -> None:
    """Add this run's figures to the cache's results file (atomically)."""
    path = cache / RESULTS_FILE
    stored: dict[str, Any] = json.loads(path.read_text()) if path.exists() else {}
    when = dt.datetime.now().astimezone().isoformat(timespec="minutes")
    for f in figures:
        stored[f"{f.kind} {f.size}"] = {
            "disk_bytes": f.disk_bytes,
            "same": f.same,
            "measured": f"stored run of {when}, syncaudit {_git_rev()}, load {load:.2f}",
            "runs": {
                n: {
                    k: getattr(r, k)
                    for k in (
                        "wall_s",
                        "cpu_s",
                        "rss_mb",
                        "pss_mb",
                        "returncode",
                        "other_cpu_s",
                        "warm_gbps",
                    )
                }
                for n, r in f.runs.items()
            },
        }
    _write_json_atomic(path, stored)


def _stored_figures(cache: Path, kind: str, size: str) -> Figures | None:
    """A container's figures at one size from an earlier run, if any."""
    path = cache / RESULTS_FILE
    entry = json.loads(path.read_text()).get(f"{kind} {size}") if path.exists() else None
    if entry is None:
        return None
    runs = {n: Run(f"{kind} {n}", [], **values) for n, values in entry["runs"].items()}
    return Figures(kind, size, entry["disk_bytes"], runs, entry["same"], entry["measured"])


def measure_container(
    kind: str,
    size: str,
    path: Path,
    facts: LogFacts,
    scratch: Path,
    timeout_s: float,
    repeat: int,
    baseline: dict[str, str] | None = None,
) -> Figures:
    """Audit, floor and limit on one container file/folder, `repeat` interleaved rounds;
    with `baseline` (an environment), the audit of another syncaudit too ("baseline")."""
    floor_argv, limit_argv = container_commands(kind, path, facts.audit_topics)
    json_out = scratch / f"audit-{kind}-{size}.json"
    contenders: list[tuple[str, list[str], dict[str, str] | None]] = [
        ("audit", audit_argv(path, json_out), None),
        ("floor", floor_argv, None),
        ("limit", limit_argv, None),
    ]
    if baseline is not None:
        base_json = scratch / f"audit-{kind}-{size}-baseline.json"
        contenders.append(("baseline", audit_argv(path, base_json), baseline))
    runs: dict[str, list[Run]] = {}
    for _ in range(repeat):
        for name, argv, env in contenders:
            warm_gbps = _warm_any(path)
            run = measure(f"{kind} {size} {name}", argv, scratch, timeout_s, env=env)
            run.warm_gbps = warm_gbps
            runs.setdefault(name, []).append(run)
    medians = {name: median_run(r) for name, r in runs.items()}
    same = "-"
    # The bare MCAP's JSON is kept in the cache: the reference of runs without it.
    reference = scratch.parent / f"reference-audit-{size}.json"
    if medians["audit"].ok:
        if kind == "mcap":
            shutil.copyfile(json_out, reference)
        same = _same_result(reference, json_out)
        if baseline is not None and medians["baseline"].ok:
            # The JSON of both versions byte for byte (the path is the same file).
            same += ", baseline's JSON " + (
                "identical" if json_out.read_bytes() == base_json.read_bytes() else "DIFFERS"
            )
    return Figures(kind, size, _disk_bytes(path), medians, same)


def bench_containers(
    cache: Path,
    logs: dict[str, LogFacts],
    scratch: Path,
    timeout_s: float,
    repeat: int,
    kinds: Sequence[str] = CONTAINERS,
    baseline: dict[str, str] | None = None,
) -> list[Figures]:
    """Audit, floor and limit on every container (of `kinds`) of each log in `logs`
    ("1x", "2x"), the sizes of one container one after the other; stored in the cache."""
    paths = {
        size: ensure_containers(cache, facts.path, scratch, timeout_s, kinds)
        for size, facts in logs.items()
    }
    load = os.getloadavg()[0]
    out: list[Figures] = []
    for kind in kinds:
        for size, facts in logs.items():
            out.append(
                measure_container(
                    kind, size, paths[size][kind], facts, scratch, timeout_s, repeat, baseline
                )
            )
    _store_figures(cache, out, load)
    return out


def _ratio(a: float, b: float) -> str:
    return f"x{a / b:.2f}" if a == a and b == b and b > 0 else "-"


def whole_file_table(figures: list[Figures]) -> list[str]:
    """Per container and size: wall, ratios, CPU and memory of the median runs."""
    head = (
        f"{'container':<17}{'log':>4}{'on disk':>10}{'audit s':>9}{'floor s':>9}{'limit s':>9}"
        f"{'audit/floor':>12}{'audit/limit':>12}{'audit MB':>10}{'CPU s audit/floor/limit':>25}"
        f"  {'others audit/floor/limit':>18}{'warm GB/s':>11}  same result as bare mcap"
    )
    lines = [head, "-" * len(head)]
    for f in figures:
        # Cores the rest of the machine kept busy during each median run, and the slowest
        # page-cache warm-up read before them (low: the file was partly read from disk).
        others = " / ".join(
            _fmt(f.runs[n].other_cpu_s / f.runs[n].wall_s, 2) if f.ok(n) else "-"
            for n in ("audit", "floor", "limit")
        )
        warm = min(f.runs[n].warm_gbps for n in ("audit", "floor", "limit") if n in f.runs)

        def wall(name: str, f: Figures = f) -> str:
            return f"{f.wall(name):.2f}" if f.ok(name) else "FAILED"

        # CPU time (user+sys of the tree) holds up better than wall on a shared machine.
        cpu = " / ".join(
            f"{f.runs[n].cpu_s:.2f}" if f.ok(n) else "-" for n in ("audit", "floor", "limit")
        )
        pss = f.runs["audit"].pss_mb if f.ok("audit") else float("nan")
        lines.append(
            f"{f.kind:<17}{f.size:>4}{_gb(f.disk_bytes):>10}{wall('audit'):>9}{wall('floor'):>9}"
            f"{wall('limit'):>9}{_ratio(f.wall('audit'), f.wall('floor')):>12}"
            f"{_ratio(f.wall('audit'), f.wall('limit')):>12}{_fmt(pss, 0):>10}{cpu:>25}"
            f"  {others:>18}{_fmt(warm, 1):>11}  {f.same}"
            + ("" if f.measured == "now" else f"  ({f.measured})")
        )
        for run in f.runs.values():
            if not run.ok and f.measured == "now":
                lines.append(f"    {run.name} FAILED: {run.error_line()}")
    return lines


def baseline_table(figures: list[Figures]) -> list[str]:
    """The audit against the baseline syncaudit's, run for run interleaved."""
    head = f"{'container':<17}{'log':>4}{'baseline s':>11}{'audit s':>9}{'change':>8}{'CPU s base/audit':>19}"
    lines = [head, "-" * len(head)]
    for f in figures:
        if "baseline" not in f.runs or f.measured != "now":
            continue
        base, new = f.runs["baseline"], f.runs["audit"]
        change = f"{new.wall_s / base.wall_s - 1:+.0%}" if base.ok and new.ok else "-"
        cpu = f"{_fmt(base.cpu_s, 2)} / {_fmt(new.cpu_s, 2)}"
        lines.append(
            f"{f.kind:<17}{f.size:>4}{_fmt(base.wall_s, 2):>11}{_fmt(new.wall_s, 2):>9}"
            f"{change:>8}{cpu:>19}"
        )
    return lines


def per_gb_table(figures: list[Figures]) -> list[str]:
    """Per container: marginal seconds per GB (2x minus 1x) of audit, floor and limit,
    their ratios, and the audit's fixed cost they imply (issue 13 judges these apart)."""
    head = (
        f"{'container':<17}{'extra GB':>9}{'audit s/GB':>11}{'floor s/GB':>11}{'limit s/GB':>11}"
        f"{'audit/floor':>12}{'audit/limit':>12}{'audit fixed s':>14}"
        f"{'CPU s/GB audit/floor/limit':>29}"
    )
    lines = [head, "-" * len(head)]
    by_kind: dict[str, dict[str, Figures]] = {}
    for f in figures:
        by_kind.setdefault(f.kind, {})[f.size] = f
    for kind, sizes in by_kind.items():
        one, two = sizes.get("1x"), sizes.get("2x")
        if one is None or two is None:
            lines.append(f"{kind:<17}  no per-GB figures: the {'2x' if one else '1x'} log not run")
            continue
        extra_gb = (two.disk_bytes - one.disk_bytes) / 1e9
        rate = {n: (two.wall(n) - one.wall(n)) / extra_gb for n in ("audit", "floor", "limit")}
        fixed = one.wall("audit") - rate["audit"] * one.disk_bytes / 1e9
        cpu = " / ".join(
            f"{(two.runs[n].cpu_s - one.runs[n].cpu_s) / extra_gb:.2f}"
            if one.ok(n) and two.ok(n)
            else "-"
            for n in ("audit", "floor", "limit")
        )
        lines.append(
            f"{kind:<17}{extra_gb:>9.2f}{_fmt(rate['audit'], 3):>11}{_fmt(rate['floor'], 3):>11}"
            f"{_fmt(rate['limit'], 3):>11}{_ratio(rate['audit'], rate['floor']):>12}"
            f"{_ratio(rate['audit'], rate['limit']):>12}{_fmt(fixed, 2):>14}{cpu:>29}"
        )
    return lines


def _same_result(reference: Path, other: Path) -> str:
    """Whether two audit JSONs agree apart from the log's path and container."""

    def strip(value: Any) -> Any:
        if isinstance(value, dict):
            return {k: strip(v) for k, v in value.items() if k not in ("path", "container")}
        if isinstance(value, list):
            return [strip(v) for v in value]
        return value

    try:
        a, b = (strip(json.loads(p.read_text())) for p in (reference, other))
    except (OSError, ValueError) as exc:
        return f"not checked ({exc})"
    return "yes" if a == b else "NO: the audit results differ"


# =================================================================================== main


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        description="Benchmark `syncaudit audit` against the bare-mcap floor, the all-cores "
        "decompression limit and two peers, on a large simulated log (issue 5)."
    )
    parser.add_argument("--size-gb", type=float, default=2.0, help="1x log size (default 2.0)")
    parser.add_argument("--cache-dir", type=Path, default=DEFAULT_CACHE, help="logs and venv")
    parser.add_argument("--skip-peers", action="store_true", help="do not run the peers")
    parser.add_argument("--quick", action="store_true", help=f"a ~{QUICK_GB:g} GB smoke test")
    parser.add_argument(
        "--timeout-s", type=float, default=3_600.0, help="per contender (default 3600)"
    )
    parser.add_argument(
        "--repeat",
        type=int,
        default=DEFAULT_REPEAT,
        help=f"interleaved rounds; each figure is the median-wall run (default {DEFAULT_REPEAT})",
    )
    parser.add_argument(
        "--skip-containers",
        action="store_true",
        help="do not convert the 1x log to the other containers and audit each",
    )
    parser.add_argument(
        "--containers",
        default=",".join(CONTAINERS),
        help=f"comma-separated containers to convert and audit (default all: {','.join(CONTAINERS)})",
    )
    parser.add_argument(
        "--only-containers",
        action="store_true",
        help="skip the bare-MCAP rounds (audit, floor, limit, peers, 2x log): containers only",
    )
    parser.add_argument(
        "--sizes",
        default="1x,2x",
        help="container logs to measure: 1x, 2x or 1x,2x (default); a size not run takes the "
        f"figures stored by the last run that did (in CACHE/{RESULTS_FILE}) for the per-GB table",
    )
    parser.add_argument(
        "--skip-bz2",
        action="store_true",
        help="leave out the ROS 1 bz2 bag (minutes per run; its conversion too)",
    )
    parser.add_argument(
        "--baseline-src",
        type=Path,
        help="containers: also audit with syncaudit imported from this src folder (e.g. "
        "`git archive <commit> src | tar -x -C DIR`), interleaved: before/after",
    )
    parser.add_argument(
        "--dense",
        action="store_true",
        help="the dense long-drive shape instead (benchmarks/dense_shape.py: 32- and "
        "128-beam LiDARs, six cameras at 10 Hz, 10/60/120-minute logs, one bag)",
    )
    parser.add_argument(
        "--minutes",
        default="10,60,120",
        help="--dense: log lengths in minutes (the middle one is the timed log)",
    )
    parser.add_argument(
        "--dense-parts",
        default="mcap,bag,memory,html",
        help="--dense: what to run: mcap and bag (the rounds on the middle length), memory, "
        "html (default all)",
    )
    parser.add_argument("--generate-to", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--convert-to", choices=CONTAINERS, help=argparse.SUPPRESS)
    parser.add_argument("--convert-from", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--convert-dst", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--duration-s", type=float, help=argparse.SUPPRESS)
    return parser.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(argv)
    if args.generate_to is not None:
        if args.dense:
            from dense_shape import generate_dense

            generate_dense(args.generate_to, args.duration_s)
        else:
            generate(args.generate_to, args.duration_s)
        return 0
    if args.convert_to is not None:
        convert_container(args.convert_from, args.convert_to, args.convert_dst)
        return 0
    if not Path("/proc/self/smaps_rollup").exists():
        raise SystemExit("this benchmark samples memory from /proc (Linux 4.14+)")
    size_gb = QUICK_GB if args.quick else args.size_gb
    cache: Path = args.cache_dir.resolve()
    with _cache_lock(cache):
        _drop_stale_temporaries(cache)
        scratch = cache / "run"
        shutil.rmtree(scratch, ignore_errors=True)
        scratch.mkdir()
        if args.dense:
            from dense_shape import bench_dense

            return bench_dense(args, cache, scratch)
        return _bench(args, size_gb, cache, scratch)


def _bench(args: argparse.Namespace, size_gb: float, cache: Path, scratch: Path) -> int:
    started = dt.datetime.now().astimezone().isoformat(timespec="seconds")
    _log(
        f"syncaudit audit benchmark  {started}  syncaudit {_git_rev()}  "
        f"{os.cpu_count()} cores, {_memory_gib():.1f} GiB RAM, Python {platform.python_version()}, "
        f"load average {os.getloadavg()[0]:.2f} (1 min; others' work on the machine skews times)"
    )
    sizes = {s.strip() for s in args.sizes.split(",") if s.strip()}
    one_only = args.only_containers and "2x" not in sizes
    one_meta, two_meta = prepare_logs(
        cache, size_gb, scratch, args.timeout_s, two_needed=not one_only
    )
    one = log_facts(Path(one_meta["log"]))
    _log(
        f"rig: {LIDAR_MODEL} (VelodyneScan, random returns), {len(CAMERAS)} cameras "
        f"(CompressedImage {IMAGE_BYTES / 1e3:.0f} KB JPEG-like, exposure, trigger, flir meta)"
    )
    _log(describe_log("1x", one_meta, one))
    if two_meta is None:
        logs = {"1x": one}
    else:
        two = log_facts(Path(two_meta["log"]))
        _log(describe_log("2x", two_meta, two))
        logs = {"1x": one, "2x": two}

    kinds = [k.strip() for k in args.containers.split(",") if k.strip()]
    if args.skip_bz2:
        kinds = [k for k in kinds if k != "ros1-bz2"]
    unknown = [k for k in kinds if k not in CONTAINERS]
    if unknown:
        raise SystemExit(
            f"--containers: unknown {', '.join(unknown)} (known: {', '.join(CONTAINERS)})"
        )
    if args.only_containers:
        warm_bytecode(*([args.baseline_src] if args.baseline_src is not None else []))
        return _bench_containers(args, cache, logs, scratch, kinds)

    bin_dir: Path | None = None
    peer_note = "skipped (--skip-peers)"
    if not args.skip_peers:
        bin_dir, peer_note = ensure_peers(cache, scratch)

    bytecode = warm_bytecode(*([args.baseline_src] if args.baseline_src is not None else []))
    _log(
        f"syncaudit bytecode {bytecode}; each contender's log is read once right before it "
        "runs (page cache warm)"
    )
    repeat = max(1, args.repeat)
    _log(
        f"running {repeat} interleaved round(s) of: audit, floor, limit"
        + (", peers" if bin_dir else "")
        + ", audit and floor on 2x ..."
    )
    t_out = args.timeout_s
    json_1x, json_2x = scratch / "audit-1x.json", scratch / "audit-2x.json"
    floor_argv = [sys.executable, "-c", FLOOR_CODE, str(one.path), *one.audit_topics]
    floor2_argv = [sys.executable, "-c", FLOOR_CODE, str(two.path), *two.audit_topics]
    limit_argv = [sys.executable, "-c", MCAP_LIMIT, str(one.path)]
    cores = f"limit: {os.cpu_count()}-core decompress"
    rounds: dict[str, list[Run]] = {}
    for _ in range(repeat):
        round_runs = [
            measure(
                "syncaudit audit", audit_argv(one.path, json_1x), scratch, t_out, warm=one.path
            ),
            measure("floor: bare mcap iteration", floor_argv, scratch, t_out, warm=one.path),
            measure(cores, limit_argv, scratch, t_out, warm=one.path),
            *(peer_runs(bin_dir, one.path, scratch, t_out) if bin_dir else []),
            measure(
                "syncaudit audit @2x log",
                audit_argv(two.path, json_2x),
                scratch,
                t_out,
                warm=two.path,
            ),
            measure("floor @2x log", floor2_argv, scratch, t_out, warm=two.path),
        ]
        for run in round_runs:
            rounds.setdefault(run.name, []).append(run)
    median = {name: median_run(runs) for name, runs in rounds.items()}
    audit, floor, limit = (
        median["syncaudit audit"],
        median["floor: bare mcap iteration"],
        median[cores],
    )
    audit2, floor2 = median["syncaudit audit @2x log"], median["floor @2x log"]
    peers = [median[name] for name in ("rosbag-doctor", "clockdoctor") if name in median]
    runs = [audit, floor, limit, *peers, audit2, floor2]
    rows = [(run, two if run in (audit2, floor2) else one) for run in runs]

    _log()
    _log(table(rows))
    warm = [run.warm_gbps for run in runs]
    _log(
        "wall: elapsed; CPU: user+sys incl. reaped children (wait4); RSS/PSS: peak over time of "
        f"the process tree's sum, sampled every {SAMPLE_S * 1e3:.0f} ms (RSS also >= ru_maxrss); "
        f"MB/s: file bytes / wall; msg/s: messages on the audit's topics / wall; others: cores "
        f"the rest of the machine kept busy meanwhile (of {os.cpu_count()}; the benchmark's "
        f"sampler included); warm-up reads before the runs {min(warm):.1f}-{max(warm):.1f} GB/s"
    )
    for run in runs:
        if not run.ok:
            _log(f"{run.name} FAILED: {run.error_line()}")
    if floor.ok and not floor.stdout.strip().endswith(str(one.audit_messages)):
        _log(
            f"note: the floor counted {floor.stdout.strip()} messages, expected {one.audit_messages}"
        )
    if audit.ok:
        _log(audit_vs_truth(json_1x, one.path) + " (1x)")
    if audit2.ok:
        _log(audit_vs_truth(json_2x, two.path) + " (2x)")

    if repeat > 1:
        _log(
            "wall s of every round (the table shows each contender's median run): "
            + "; ".join(
                f"{name.split(':')[0]} " + " ".join(f"{r.wall_s:.2f}" for r in rs)
                for name, rs in rounds.items()
            )
        )
    _log(marginal_cost(audit, audit2, floor, floor2, one, two))

    _log()
    ratios = []
    for other in (floor, limit, *peers):
        if audit.ok and other.ok:
            ratios.append(f"audit/{other.name.split(':')[0]} x{audit.wall_s / other.wall_s:.2f}")
    _log("ratios (wall time): " + ("  ".join(ratios) if ratios else "none (failures above)"))
    if audit.ok:
        _log(
            f"audit throughput: {one.size_bytes / MB / audit.wall_s:,.0f} MB/s, "
            f"{one.audit_messages / audit.wall_s:,.0f} msg/s (1x)"
            + (
                f"; {two.size_bytes / MB / audit2.wall_s:,.0f} MB/s, "
                f"{two.audit_messages / audit2.wall_s:,.0f} msg/s (2x)"
                if audit2.ok
                else ""
            )
        )
        _log(
            f"audit peak memory: 1x RSS {audit.rss_mb:.0f} MB / PSS {audit.pss_mb:.0f} MB, "
            + (
                f"2x RSS {audit2.rss_mb:.0f} MB / PSS {audit2.pss_mb:.0f} MB "
                f"({audit2.pss_mb / audit.pss_mb - 1.0:+.1%} PSS)"
                if audit2.ok
                else "2x failed"
            )
        )
    if peers or peer_note.startswith("installing"):
        _log(f"peers venv: {peer_note}")
    _log()
    _log("targets:")
    for line in verdicts(audit, floor, limit, audit2, peers, peer_note):
        _log("  " + line)
    if not args.skip_containers:
        _bench_containers(args, cache, logs, scratch, kinds)
    return 0 if audit.ok else 1


def _bench_containers(
    args: argparse.Namespace,
    cache: Path,
    logs: dict[str, LogFacts],
    scratch: Path,
    kinds: Sequence[str],
) -> int:
    """The container tables (issue 13): whole-file and per GB; 0."""
    repeat = max(1, args.repeat)
    sizes = [s.strip() for s in args.sizes.split(",") if s.strip()]
    if not set(sizes) <= {"1x", "2x"} or not sizes:
        raise SystemExit(f"--sizes: {args.sizes!r}, expected 1x, 2x or 1x,2x")
    _log()
    _log(
        "every container (issue 13), the 1x and 2x logs converted once with rosbags (writer for "
        "the ROS 2 folders, rosbags-convert for ROS 1); floor: the container's standard library "
        f"(mcap, sqlite3, rosbags) in one process; limit: {os.cpu_count()} processes reading "
        "(and decompressing) every chunk/row; median of "
        f"{repeat} round(s), load average {os.getloadavg()[0]:.2f} at the start:"
    )
    run_logs = {size: logs[size] for size in sizes}
    baseline = None
    if args.baseline_src is not None:
        baseline = dict(os.environ, PYTHONPATH=str(args.baseline_src.resolve()))
        _log(f"baseline: the audit also run with syncaudit from {args.baseline_src}")
    figures = bench_containers(
        cache, run_logs, scratch, args.timeout_s, repeat, kinds, baseline=baseline
    )
    # Sizes not run now: the last stored figures, marked with when they were measured.
    for kind in kinds:
        for size in ("1x", "2x"):
            if size not in sizes and (stored := _stored_figures(cache, kind, size)) is not None:
                figures.append(stored)
    figures.sort(key=lambda f: (CONTAINERS.index(f.kind), f.size))
    _log("whole file:")
    for line in whole_file_table(figures):
        _log(line)
    _log()
    _log(
        "per GB (2x log minus 1x log, each container's own files; fixed = audit 1x - rate x size):"
    )
    for line in per_gb_table(figures):
        _log(line)
    if baseline is not None:
        _log()
        _log("the audit against the baseline (same rounds, interleaved; medians):")
        for line in baseline_table(figures):
            _log(line)
    _log(f"load average at the end: {os.getloadavg()[0]:.2f} (1 min)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
