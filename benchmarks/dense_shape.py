"""The dense long-drive shape of `bench_audit.py --dense` (issue 28); prints its figures.

Real drives are long and dense: tens of minutes to hours, several LiDARs, six or more
cameras at 10-30 Hz with exposure and trigger records per frame. This shape is a VLS-128
(128 beams, the trigger LiDAR) and a VLP-32C (32 beams, on its own topic), six cameras
at 10 Hz with small compressed images, exposure metadata (two kinds) and trigger records.

What one run does:

1. Generates (once, cached in `--cache-dir`) the shape at each of `--minutes` (default
   10, 60, 120) as MCAP (zstd chunks), and the middle length also as a ROS 1 bag with lz4
   chunks (`rosbag record --lz4`), each with its truth and rig file.
2. On the middle length, in MCAP and in the bag, `--repeat` interleaved rounds of: the
   audit; the audit with syncaudit from `--baseline-src` (before/after); the bare floor
   (every message iterated by the container's standard library, one process, nothing
   done per message); the decode limit (the audited topics' messages read and
   deserialised by rosbags on all cores: what an audit that must look inside every
   message it uses cannot go below); and the peers rosbag-doctor and clockdoctor.
3. The audit once on every length: peak RSS of its largest process and of its process
   tree, and the growth of the largest process per camera frame between the lengths.
4. `--html` on the longest log: the report's size and the time headless Chromium takes to
   load it (`--dump-dom`: parse, scripts, layout) minus that of an empty page.

Every figure printed is measured in that run; the verdict lines compare them with the
issue's targets.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import sys
import time
from pathlib import Path
from typing import Any

import bench_audit as ba

DENSE_VERSION = 1
"""Bump when the generated logs change: cached logs carry it in their names."""
DENSE_CAMERAS: tuple[tuple[str, float, float], ...] = ba.CAMERAS
EXTRA_LIDAR = {
    "model": "VLP-32C",
    "topic": "/rear/velodyne_packets",
    "frame_id": "lidar_rear",
    "start_azimuth_deg": 200.0,
}
TARGET_FLOOR_RATIO = 1.0
TARGET_LARGEST_MB = 300.0
TARGET_BYTES_PER_FRAME = 200.0
TARGET_HTML_MB = 10.0
TARGET_RENDER_S = 3.0

FLOOR_ALL_MCAP = """\
import sys
from mcap.reader import make_reader

count = 0
with open(sys.argv[1], "rb") as f:
    for _ in make_reader(f).iter_messages():
        count += 1
print(count)
"""
"""Floor: mcap's reader iterating every message of the file (one process)."""

FLOOR_ALL_BAG = """\
import sys
from pathlib import Path
from rosbags.rosbag1 import Reader

count = 0
with Reader(Path(sys.argv[1])) as reader:
    for _conn, _t, _data in reader.messages():
        count += 1
print(count)
"""
"""Floor of the bag: rosbags' reader yielding every message's bytes (one process)."""

DECODE_LIMIT = """\
import multiprocessing, os, re, sys
from pathlib import Path

from rosbags.typesys import Stores, get_types_from_msg, get_typestore

SECTION = re.compile(r"^=+\\s*$", re.M)


def types_of(text, name):
    # A ROS message definition with its dependencies: sections after "MSG: pkg/Type".
    out = {}
    for i, part in enumerate(SECTION.split(text)):
        part = part.strip()
        if i == 0:
            out.update(get_types_from_msg(part, name))
            continue
        head, _, body = part.partition("\\n")
        dep = head.removeprefix("MSG:").strip()
        if "/msg/" not in dep:
            dep = dep.replace("/", "/msg/")
        out.update(get_types_from_msg(body, dep))
    return out


STORE = None


def work(job):
    path, topics, lo, hi = job
    count = 0
    if path.endswith(".mcap"):
        from mcap.reader import make_reader

        with open(path, "rb") as f:
            reader = make_reader(f)
            for schema, channel, message in reader.iter_messages(
                topics=topics, starting_at=lo, ending_before=hi, log_time_order=False
            ):
                STORE.deserialize_cdr(message.data, msgtype(schema.name))
                count += 1
    else:
        from rosbags.rosbag1 import Reader

        with Reader(Path(path)) as reader:
            conns = [c for c in reader.connections if c.topic in topics]
            for conn, _t, data in reader.messages(connections=conns, start=lo, stop=hi):
                STORE.deserialize_ros1(data, conn.msgtype)
                count += 1
    return count


def msgtype(name):
    return name if "/msg/" in name else name.replace("/", "/msg/", 1)


def register(path, topics):
    global STORE
    types = {}
    if path.endswith(".mcap"):
        from mcap.reader import make_reader

        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
        for channel in summary.channels.values():
            if channel.topic in topics:
                schema = summary.schemas[channel.schema_id]
                types.update(types_of(schema.data.decode(), msgtype(schema.name)))
        start = min(c.message_start_time for c in summary.chunk_indexes)
        end = max(c.message_end_time for c in summary.chunk_indexes) + 1
    else:
        from rosbags.rosbag1 import Reader

        with Reader(Path(path)) as reader:
            for conn in reader.connections:
                if conn.topic in topics:
                    msgdef = getattr(conn.msgdef, "data", conn.msgdef)  # rosbags >= 0.10
                    types.update(types_of(msgdef, conn.msgtype))
            start, end = reader.start_time, reader.end_time + 1
    STORE = get_typestore(Stores.ROS1_NOETIC if not path.endswith(".mcap") else Stores.ROS2_HUMBLE)
    STORE.register({k: v for k, v in types.items() if k not in STORE.types})
    return start, end


if __name__ == "__main__":
    path, topics, workers = sys.argv[1], sys.argv[2:], os.cpu_count() or 1
    start, end = register(path, topics)
    n = 8 * workers
    edges = [start + (end - start) * i // n for i in range(n + 1)]
    jobs = [(path, topics, edges[i], edges[i + 1]) for i in range(n)]
    with multiprocessing.get_context("fork").Pool(workers) as pool:
        print(sum(pool.imap_unordered(work, jobs)))
"""
"""The decode limit: the audited topics' messages read and deserialised by rosbags (its
generated deserialisers; fixed-size byte arrays as numpy arrays) on all cores, the log
split into 8 time ranges per core."""


# ================================================================================ the logs


def dense_config(duration_s: float, fmt: str) -> dict[str, Any]:
    """The simulator configuration of a dense log (JSON form of SyncSimConfig)."""
    return {
        "seed": 7,
        "duration_s": duration_s,
        "log_format": fmt,
        "bag_compression": "lz4" if fmt == "bag" else "none",
        "overwrite": True,
        "lidar_model": "VLS-128",
        "zero_azimuth_deg": ba.ZERO_AZIMUTH_DEG,
        "extra_lidars": [EXTRA_LIDAR],
        "image_kind": "compressed",
        "cameras": [
            {"name": name, "yaw_deg": yaw, "delay_error_us": error}
            for name, yaw, error in DENSE_CAMERAS
        ],
    }


def generate_dense(out: Path, duration_s: float) -> None:
    """Simulate one dense log, its truth and rig file (run in a measured subprocess)."""
    import yaml

    from syncaudit.simulate.rig_file import rig_from_truth
    from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log
    from syncaudit.writers.atomic import write_text_atomic
    from syncaudit.writers.provenance import COMMENT_MARK

    fmt = "bag" if out.suffix == ".bag" else "mcap"
    config = SyncSimConfig.model_validate(dense_config(duration_s, fmt))
    truth = simulate_sync_log(out, config)
    rig = rig_from_truth(truth).model_dump(mode="json", exclude_defaults=True)
    write_text_atomic(ba.rig_path(out), COMMENT_MARK + yaml.safe_dump(rig, sort_keys=False))


def _key() -> str:
    payload = json.dumps([DENSE_VERSION, dense_config(0.0, "mcap")], sort_keys=True)
    return hashlib.sha256(payload.encode()).hexdigest()[:10]


def ensure_dense(
    cache: Path, minutes: int, suffix: str, scratch: Path, timeout_s: float
) -> dict[str, Any]:
    """The cached dense log of `minutes` (generated if absent) and its metadata."""
    log = cache / f"dense_{minutes}min_{_key()}{suffix}"
    meta_file = ba.meta_path(log)
    if meta_file.exists() and log.exists() and ba.rig_path(log).exists():
        meta: dict[str, Any] = json.loads(meta_file.read_text())
        meta["cached"] = True
        return meta
    ba._log(f"generating {log.name} ({minutes} min) ...")
    argv = [
        sys.executable,
        str(Path(__file__).resolve().with_name("bench_audit.py")),
        "--dense",
        "--generate-to",
        str(log),
        "--duration-s",
        repr(60.0 * minutes),
    ]
    run = ba.measure(f"generate {log.name}", argv, scratch, timeout_s, cwd=ba.REPO)
    if not run.ok:
        raise SystemExit(f"generating {log} failed: {run.error_line()}")
    meta = {
        "log": str(log),
        "minutes": minutes,
        "size_bytes": log.stat().st_size,
        "generation": {"wall_s": run.wall_s, "cpu_s": run.cpu_s, "peak_rss_mb": run.rss_mb},
    }
    ba._write_json_atomic(meta_file, meta)
    meta["cached"] = False
    return meta


# ============================================================================= contenders


def _audit_argv(log: Path, json_out: Path, *extra: str) -> list[str]:
    return [*ba.audit_argv(log, json_out), *extra]


def contenders(
    log: Path, scratch: Path, baseline: dict[str, str] | None
) -> list[tuple[str, list[str], dict[str, str] | None]]:
    """(name, argv, env) of every contender on one log (peers apart)."""
    py = sys.executable
    is_bag = log.suffix == ".bag"
    out = [
        ("syncaudit audit", _audit_argv(log, scratch / f"audit-{log.suffix[1:]}.json"), None),
    ]
    if baseline is not None:
        json_out = scratch / f"baseline-{log.suffix[1:]}.json"
        out.append(("baseline audit", _audit_argv(log, json_out), baseline))
    out += [
        (
            "floor: every message",
            [py, "-c", FLOOR_ALL_BAG if is_bag else FLOOR_ALL_MCAP, str(log)],
            None,
        ),
        (
            f"decode limit: {os.cpu_count()} cores",
            [py, "-c", DECODE_LIMIT, str(log), *ba.rig_topics(ba.rig_path(log))],
            None,
        ),
    ]
    return out


def rounds(
    log: Path,
    scratch: Path,
    repeat: int,
    timeout_s: float,
    baseline: dict[str, str] | None,
    peers_bin: Path | None,
) -> dict[str, list[ba.Run]]:
    """`repeat` interleaved rounds of every contender (and the peers) on `log`."""
    runs: dict[str, list[ba.Run]] = {}
    for _ in range(repeat):
        for name, argv, env in contenders(log, scratch, baseline):
            run = ba.measure(name, argv, scratch, timeout_s, warm=log, env=env)
            runs.setdefault(name, []).append(run)
        if peers_bin is not None:
            for run in ba.peer_runs(peers_bin, log, scratch, timeout_s):
                runs.setdefault(run.name, []).append(run)
    return runs


def _frames(json_out: Path) -> int:
    """Camera frames the audit read (every camera's frames_total)."""
    result = json.loads(json_out.read_text())
    return sum(int(cam.get("frames_total") or 0) for cam in result.get("cameras", []))


# ================================================================================== report


def _line(run: ba.Run) -> str:
    state = "ok" if run.ok else f"FAILED ({run.error_line()})"
    return (
        f"  {run.name:<26}{run.wall_s:>9.2f}{run.cpu_s:>9.2f}{run.cpu_s / run.wall_s:>9.2f}"
        f"{run.largest_mb:>11.0f}{run.rss_mb:>9.0f}{run.other_cpu_s / run.wall_s:>8.2f}  {state}"
    )


HEAD = (
    f"  {'contender':<26}{'wall s':>9}{'CPU s':>9}{'CPU/wall':>9}{'largest MB':>11}"
    f"{'tree MB':>9}{'others':>8}"
)


def bench_dense(args: argparse.Namespace, cache: Path, scratch: Path) -> int:
    """The dense shape's benchmark (see the module docstring); 0 when the audits ran."""
    minutes = sorted({int(m) for m in args.minutes.split(",") if m.strip()})
    timed = minutes[len(minutes) // 2]
    ba._log(
        f"syncaudit dense benchmark  {time.strftime('%Y-%m-%d %H:%M')}  syncaudit {ba._git_rev()}  "
        f"{os.cpu_count()} cores, {ba._memory_gib():.1f} GiB RAM, load {os.getloadavg()[0]:.2f}"
    )
    ba._log(
        "shape: VLS-128 (trigger LiDAR) + VLP-32C on its own topic, six cameras at 10 Hz "
        "(small CompressedImage, CameraExposure, ImageMetaData, TriggerEvent)"
    )
    logs = {m: ensure_dense(cache, m, ".mcap", scratch, args.timeout_s) for m in minutes}
    parts = {p.strip() for p in args.dense_parts.split(",") if p.strip()}
    bag = ensure_dense(cache, timed, ".bag", scratch, args.timeout_s) if "bag" in parts else None
    for meta in [*logs.values(), *([bag] if bag else [])]:
        gen = meta["generation"]
        ba._log(
            f"  {Path(meta['log']).name}: {meta['size_bytes'] / 1e9:.2f} GB (generated in "
            f"{gen['wall_s']:.0f} s, {gen['peak_rss_mb'] / 1e3:.1f} GB peak)"
        )
    peers_bin: Path | None = None
    peer_note = "skipped (--skip-peers)"
    if not args.skip_peers:
        peers_bin, peer_note = ba.ensure_peers(cache, scratch)
    baseline = None
    if args.baseline_src is not None:
        baseline = dict(os.environ, PYTHONPATH=str(args.baseline_src.resolve()))
    ba._log(f"bytecode {ba.warm_bytecode(*([args.baseline_src] if args.baseline_src else []))}")
    repeat = max(1, args.repeat)

    verdicts: list[str] = []
    timed_logs = [Path(logs[timed]["log"])] if "mcap" in parts else []
    timed_logs += [Path(bag["log"])] if bag else []
    for log in timed_logs:
        ba._log("")
        ba._log(f"{log.name}: {repeat} interleaved round(s), medians (page cache warm):")
        runs = rounds(log, scratch, repeat, args.timeout_s, baseline, peers_bin)
        median = {name: ba.median_run(rs) for name, rs in runs.items()}
        ba._log(HEAD)
        for run in median.values():
            ba._log(_line(run))
        ba._log(
            "  wall s of every round: "
            + "; ".join(
                f"{n.split(':')[0]} " + " ".join(f"{r.wall_s:.1f}" for r in rs)
                for n, rs in runs.items()
            )
        )
        audit = median["syncaudit audit"]
        floor = median["floor: every message"]
        limit = next(r for n, r in median.items() if n.startswith("decode limit"))
        kind = "MCAP" if log.suffix == ".mcap" else "ROS 1 lz4 bag"
        if audit.ok and floor.ok:
            ratio = audit.wall_s / floor.wall_s
            limit_text = (
                f"decode limit {limit.wall_s:.1f} s (audit x{audit.wall_s / limit.wall_s:.2f})"
                if limit.ok
                else f"decode limit failed ({limit.error_line()})"
            )
            verdicts.append(
                f"{ba._mark(ratio <= TARGET_FLOOR_RATIO)} {kind}: audit <= {TARGET_FLOOR_RATIO:.1f}x the "
                f"bare floor: x{ratio:.2f} ({audit.wall_s:.1f} s vs {floor.wall_s:.1f} s); {limit_text}"
            )
        if "baseline audit" in median and median["baseline audit"].ok and audit.ok:
            base = median["baseline audit"]
            verdicts.append(
                f"[info] {kind}: before/after: baseline {base.wall_s:.1f} s, {base.largest_mb:.0f} MB "
                f"-> {audit.wall_s:.1f} s, {audit.largest_mb:.0f} MB (x{audit.wall_s / base.wall_s:.2f})"
            )
        for name in ("rosbag-doctor", "clockdoctor"):
            peer = median.get(name)
            if peer is None:
                verdicts.append(f"[no data] {kind}: faster than {name}: {peer_note}")
            elif not peer.ok:
                verdicts.append(f"[no data] {kind}: faster than {name}: {peer.error_line()}")
            elif audit.ok:
                verdicts.append(
                    f"{ba._mark(audit.wall_s < peer.wall_s)} {kind}: faster than {name}: "
                    f"{audit.wall_s:.1f} s vs {peer.wall_s:.1f} s (x{audit.wall_s / peer.wall_s:.2f})"
                )

    if "memory" in parts:
        verdicts += _memory(args, logs, minutes, scratch)
    if "html" in parts:
        verdicts += _html(args, Path(logs[minutes[-1]]["log"]), minutes[-1], scratch)
    ba._log("")
    ba._log("targets:")
    for line in verdicts:
        ba._log("  " + line)
    ba._log(f"load average at the end: {os.getloadavg()[0]:.2f} (1 min)")
    return 0


def _memory(
    args: argparse.Namespace, logs: dict[int, dict[str, Any]], minutes: list[int], scratch: Path
) -> list[str]:
    """The audit once on every length: peak memory and its growth per camera frame."""
    verdicts: list[str] = []
    ba._log("")
    ba._log("memory: the audit once on every length (largest process; tree = sum over processes)")
    mem: dict[int, tuple[ba.Run, int]] = {}
    for m in minutes:
        log = Path(logs[m]["log"])
        json_out = scratch / f"mem-{m}.json"
        run = ba.measure(
            f"audit {m} min", _audit_argv(log, json_out), scratch, args.timeout_s, warm=log
        )
        frames = _frames(json_out) if run.ok else 0
        mem[m] = (run, frames)
        ba._log(
            f"  {m:>4} min: largest {run.largest_mb:.0f} MB, tree {run.rss_mb:.0f} MB, "
            f"{frames:,} camera frames, {run.wall_s:.1f} s wall, {run.cpu_s:.1f} CPU s"
            + ("" if run.ok else f"  FAILED ({run.error_line()})")
        )
    first, last = minutes[0], minutes[-1]
    (run_a, frames_a), (run_b, frames_b) = mem[first], mem[last]
    if run_a.ok and run_b.ok and frames_b > frames_a:
        per_frame = (run_b.largest_mb - run_a.largest_mb) * ba.MB / (frames_b - frames_a)
        verdicts.append(
            f"{ba._mark(run_b.largest_mb < TARGET_LARGEST_MB)} peak memory (largest process) < "
            f"{TARGET_LARGEST_MB:.0f} MB at {last} min: {run_b.largest_mb:.0f} MB"
        )
        verdicts.append(
            f"{ba._mark(per_frame <= TARGET_BYTES_PER_FRAME)} growth <= {TARGET_BYTES_PER_FRAME:.0f} B "
            f"per camera frame ({first} -> {last} min): {per_frame:.0f} B"
        )
    return verdicts


def _html(args: argparse.Namespace, longest: Path, last: int, scratch: Path) -> list[str]:
    """`--html` on the longest log: its size and Chromium's load time."""
    verdicts: list[str] = []
    ba._log("")
    page = scratch / "dense.html"
    run = ba.measure(
        "audit --html",
        _audit_argv(longest, scratch / "html.json", "--html", str(page)),
        scratch,
        args.timeout_s,
        warm=longest,
    )
    if run.ok and page.exists():
        empty = scratch / "empty.html"
        empty.write_text("<!doctype html><title>empty</title>")
        from bench_report import CHROMIUM, _median_s  # Chromium's load time, as bench_report

        load_s = _median_s(page, 3) - _median_s(empty, 3) if CHROMIUM else float("nan")
        size_mb = page.stat().st_size / ba.MB
        ba._log(
            f"--html on {last} min: {size_mb:.2f} MB, Chromium load {load_s:.2f} s (minus an empty page)"
        )
        verdicts.append(
            f"{ba._mark(size_mb < TARGET_HTML_MB)} --html < {TARGET_HTML_MB:.0f} MB at {last} min: {size_mb:.2f} MB"
        )
        verdicts.append(
            f"{ba._mark(load_s < TARGET_RENDER_S)} renders in Chromium < {TARGET_RENDER_S:.0f} s: {load_s:.2f} s"
        )
    else:
        verdicts.append(f"[no data] --html: the audit failed ({run.error_line()})")
    return verdicts
