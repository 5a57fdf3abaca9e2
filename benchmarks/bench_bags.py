"""Read the audited topics of a ROS 1 bag or a SQLite rosbag2 bag: our readers vs the floors.

    python benchmarks/bench_bags.py LOG RIG [--rounds N]

LOG is a ROS 1 `.bag` or a rosbag2 SQLite folder/`.db3`; RIG names the audited topics (the
LiDAR topic and each camera's image, exposure and trigger topics). Printed, best of N warm
rounds, wall and CPU seconds (the pool's workers included) and MB/s of payload:

- `rosbags`: rosbags' reader alone (its index, every message of the topics, bytes touched);
- `sqlite3` (SQLite only): one `SELECT ... WHERE topic_id IN (..) ORDER BY timestamp` with
  the stdlib, the container's own floor;
- `ours serial`: `open_log(LOG).messages(topics)`, log-time order;
- `ours units xP`: `read_units` + the per-worker reader in P processes (units grouped into
  2 x P tasks by cost), messages counted in the workers as collect would decode them there.
"""

from __future__ import annotations

import argparse
import resource
import sqlite3
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import yaml

from syncaudit.logs import open_log
from syncaudit.logs.model import ChannelInfo, ReadUnit
from syncaudit.logs.ros1.format import Rosbag1ChunkReader
from syncaudit.logs.ros2.sqlite_rows import SqliteRowsReader

Stats = tuple[int, int]  # messages, payload bytes


def rig_topics(rig: Path) -> frozenset[str]:
    doc = yaml.safe_load(rig.read_text())
    topics = {doc["lidar"]["topic"]}
    for cam in doc.get("cameras", []):
        topics.update(
            cam[k] for k in ("image_topic", "exposure_topic", "trigger_topic") if k in cam
        )
    return frozenset(topics)


def read_rosbags(log: Path, topics: frozenset[str]) -> Stats:
    if log.suffix == ".bag":
        from rosbags.rosbag1 import Reader as Rosbag1Reader

        reader: object = Rosbag1Reader(log)
    else:
        from rosbags.rosbag2 import Reader as Rosbag2Reader

        reader = Rosbag2Reader(log)
    count = size = 0
    with reader as bag:  # type: ignore[attr-defined]
        conns = [c for c in bag.connections if c.topic in topics]
        for _c, _t, data in bag.messages(conns):
            count += 1
            size += len(data)
    return count, size


def read_sqlite_floor(log: Path, topics: frozenset[str]) -> Stats:
    path = next(log.glob("*.db3")) if log.is_dir() else log
    db = sqlite3.connect(f"file:{path}?mode=ro&immutable=1", uri=True)
    ids = [i for i, n in db.execute("SELECT id, name FROM topics") if n in topics]
    marks = ",".join("?" * len(ids))
    count = size = 0
    cursor = db.execute(
        f"SELECT topic_id, timestamp, data FROM messages WHERE topic_id IN ({marks}) "
        "ORDER BY timestamp",
        ids,
    )
    while rows := cursor.fetchmany(64):
        for _tid, _t, data in rows:
            count += 1
            size += len(data)
    db.close()
    return count, size


def read_serial(log: Path, topics: frozenset[str]) -> Stats:
    count = size = 0
    with open_log(log) as opened:
        for msg in opened.messages(topics):
            count += 1
            size += len(msg.data)
    return count, size


def _task(job: tuple[list[ReadUnit], dict[int, ChannelInfo]]) -> Stats:
    units, channels = job
    reader = Rosbag1ChunkReader() if units[0].kind == "rosbag1-chunk" else SqliteRowsReader()
    count = size = 0
    try:
        for unit in units:
            for _t, _i, _c, payload in reader.messages(unit, channels):
                count += 1
                size += len(payload)
    finally:
        reader.close()
    return count, size


def read_units(log: Path, topics: frozenset[str], processes: int) -> Stats:
    with open_log(log) as opened:
        units = opened.read_units(topics) or []
        channels = opened.unit_channels(topics)
    tasks = max(1, min(len(units), 2 * processes))
    groups: list[list[ReadUnit]] = [[] for _ in range(tasks)]
    loads = [0] * tasks
    for unit in sorted(units, key=lambda u: -u.cost):  # greedy: biggest first, lightest task
        k = loads.index(min(loads))
        groups[k].append(unit)
        loads[k] += unit.cost
    with ProcessPoolExecutor(processes) as pool:
        results = list(pool.map(_task, [(g, channels) for g in groups if g]))
    return sum(r[0] for r in results), sum(r[1] for r in results)


def _cpu_s() -> float:
    """CPU seconds of this process and its finished children (pool workers)."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def best(fn: Callable[[], Stats], rounds: int) -> tuple[float, float, Stats]:
    """Best wall seconds and best CPU seconds of `rounds` runs (CPU time is what a loaded
    machine distorts least), with the run's counts."""
    walls: list[float] = []
    cpus: list[float] = []
    stats: Stats = (0, 0)
    for _ in range(rounds):
        start, cpu = time.perf_counter(), _cpu_s()
        stats = fn()
        walls.append(time.perf_counter() - start)
        cpus.append(_cpu_s() - cpu)
    return min(walls), min(cpus), stats


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", type=Path)
    parser.add_argument("rig", type=Path)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    log: Path = args.log
    topics = rig_topics(args.rig)
    size = sum(p.stat().st_size for p in ([log] if log.is_file() else log.iterdir()))
    print(f"{log}: {size / 1e6:.0f} MB on disk, {len(topics)} audited topics")
    read_serial(log, topics)  # warm the page cache
    runs: list[tuple[str, Callable[[], Stats]]] = [
        ("rosbags", lambda: read_rosbags(log, topics)),
    ]
    if log.suffix != ".bag":
        runs.append(("sqlite3 floor", lambda: read_sqlite_floor(log, topics)))
    runs += [
        ("ours serial", lambda: read_serial(log, topics)),
        ("ours units 1P", lambda: read_units(log, topics, 1)),
        ("ours units 2P", lambda: read_units(log, topics, 2)),
    ]
    expected: Stats | None = None
    for name, fn in runs:
        seconds, cpu, stats = best(fn, args.rounds)
        expected = expected or stats
        same = "" if stats == expected else f"  MISMATCH {stats} != {expected}"
        print(
            f"  {name:15s} {seconds:6.2f} s wall  {cpu:6.2f} s CPU  "
            f"{stats[1] / 1e6 / seconds:6.0f} MB/s  {stats[0]} messages, "
            f"{stats[1] / 1e6:.0f} MB{same}"
        )


if __name__ == "__main__":
    main()
