"""Finding the logs to judge: files, ROS 2 bag folders, directories, globs and manifests.

Each log becomes a `LogJob` with its vehicle id and rig file. The vehicle comes from, in
order: the manifest, the log's own metadata (an MCAP metadata record or a ROS 2 bag's
`custom_data` with key `vehicle_id` or `vehicle`), the policy's `vehicle_pattern` on the
path. A ROS 1 bag (or a bare .db3) records no vehicle: only a manifest or the pattern can
name it. A log left without a vehicle while the policy refers to vehicles gets a warning
saying which of these to use (it is judged with the defaults). The rig comes from the
manifest, a `<log>.rig.yaml` beside the log (a remote log's by its URL), the policy's
`rigs` for the vehicle, then its `default_rig`; without any the audit guesses topics.
"""

from __future__ import annotations

import csv
import glob
import hashlib
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

from syncaudit.audit.rig_beside import local_rig_beside, rig_sidecar
from syncaudit.config import parse_text, read_text
from syncaudit.errors import ConfigError, LogOpenError, LogReadError
from syncaudit.fleet.policy import Policy
from syncaudit.remote.listing import list_logs, remote_fingerprint
from syncaudit.remote.sidecar import Sidecar
from syncaudit.remote.urls import is_url, public_url

LOG_SUFFIXES = (".mcap", ".bag", ".db3")
MANIFEST_SUFFIXES = (".csv", ".jsonl")
VEHICLE_KEYS = ("vehicle_id", "vehicle")
SAMPLE_BYTES = 1 << 20
SAMPLE_COUNT = 8


@dataclass(frozen=True, slots=True)
class LogJob:
    """One log to judge: where it is and what describes it."""

    path: str
    vehicle: str | None = None
    rig_path: str | None = None
    tags: tuple[str, ...] = ()
    source: str = "path"
    """Where the job came from: 'path' or the manifest file."""


@dataclass(slots=True)
class Discovery:
    """The jobs found, and inputs that named nothing (reported, judged as errors)."""

    jobs: list[LogJob] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    """One line per log judged without a vehicle id although the policy refers to vehicles."""


def is_bag_dir(path: Path) -> bool:
    """A ROS 2 bag folder: a directory with metadata.yaml."""
    return path.is_dir() and (path / "metadata.yaml").is_file()


def _is_log_file(path: Path) -> bool:
    if path.suffix == ".mcap" and path.parent.joinpath("metadata.yaml").is_file():
        return False  # a ROS 2 bag's storage file: the bag folder is the log
    if path.suffix == ".db3" and path.parent.joinpath("metadata.yaml").is_file():
        return False
    return path.is_file() and path.suffix in (".mcap", ".bag", ".db3")


def _walk(root: Path) -> list[Path]:
    """Logs under a directory, recursively: files and ROS 2 bag folders (not their insides)."""
    found: list[Path] = []
    for dirpath, dirnames, filenames in os.walk(root):
        here = Path(dirpath)
        if is_bag_dir(here):
            found.append(here)
            dirnames.clear()
            continue
        dirnames.sort()
        found.extend(here / n for n in sorted(filenames) if _is_log_file(here / n))
    return found


def _expand(item: str) -> list[Path] | None:
    """Paths named by one input (None: a manifest, handled by the caller)."""
    path = Path(item)
    if path.suffix in MANIFEST_SUFFIXES and path.is_file():
        return None
    if is_bag_dir(path):
        return [path]
    if path.is_dir():
        return _walk(path)
    if path.exists():
        return [path]
    if glob.has_magic(item):
        out: list[Path] = []
        for match in sorted(glob.glob(item, recursive=True)):
            p = Path(match)
            if is_bag_dir(p) or _is_log_file(p):
                out.append(p)
            elif p.is_dir():
                out.extend(_walk(p))
        return out
    return [path]  # missing: becomes that log's error row


MAX_MANIFEST_BYTES = 16 << 20
"""Largest manifest read (16 MiB)."""

MAX_MANIFEST_ROWS = 50_000
"""Most rows in one manifest (split a larger fleet): the fuzz campaign's 936,583-line
JSONL manifest took 25 s to refuse at its last line, a 2.5-million-row CSV over 30 s."""


def _csv_rows(path: Path, text: str) -> list[dict[str, object]]:
    """A CSV manifest's rows; a header naming a column twice is refused (one would win)."""
    try:
        reader = csv.DictReader(text.splitlines())
        names = reader.fieldnames
        if names is None or "path" not in names:
            raise ConfigError(f"{path}: a CSV manifest needs a header with a 'path' column")
        unknown = set(names) - {"path", "vehicle", "rig", "tags"}
        if unknown:
            raise ConfigError(f"{path}: unknown manifest column(s) {sorted(unknown)}")
        twice = sorted({name for name in names if list(names).count(name) > 1})
        if twice:
            raise ConfigError(f"{path}: manifest column(s) {twice} given twice")
        return [dict(r) for r in reader]
    except csv.Error as exc:
        raise ConfigError(f"{path}:{reader.line_num}: not CSV ({exc})") from None


def read_manifest(path: Path) -> list[LogJob]:
    """A CSV (header: path, vehicle, rig, tags) or JSONL manifest; relative paths are
    relative to the manifest. Tags are `;`-separated in CSV, a list in JSONL."""
    base = path.resolve().parent
    rows: list[dict[str, object]] = []
    text = read_text(path, what="manifest", max_bytes=MAX_MANIFEST_BYTES)
    if text.count("\n") > MAX_MANIFEST_ROWS + 1:  # counted before any row is parsed
        raise ConfigError(f"{path}: manifest of more than {MAX_MANIFEST_ROWS} rows; split it")
    if path.suffix == ".csv":
        rows = _csv_rows(path, text)
    else:
        for number, line in enumerate(text.splitlines(), 1):
            if not line.strip():
                continue
            try:
                row = parse_text(line, "JSON")  # bounded like every config, keys unique
            except ConfigError as exc:
                reason = str(exc).removeprefix("not valid JSON: ")
                raise ConfigError(f"{path}:{number}: not JSON ({reason})") from None
            if not isinstance(row, dict) or "path" not in row:
                raise ConfigError(f"{path}:{number}: each line needs an object with 'path'")
            rows.append(row)
    jobs = []
    for number, row in enumerate(rows, 2 if path.suffix == ".csv" else 1):
        log = str(row.get("path") or "").strip()
        if not log:
            raise ConfigError(f"{path}:{number}: empty path")
        tags_raw = row.get("tags") or ()
        items: list[object] = (
            list(tags_raw.split(";"))
            if isinstance(tags_raw, str)
            else list(tags_raw)
            if isinstance(tags_raw, (list, tuple))
            else [tags_raw]
        )
        tags = tuple(str(t) for t in items if t)
        rig = row.get("rig") or None
        jobs.append(
            LogJob(
                path=str(base / log) if not os.path.isabs(log) else log,
                vehicle=str(row["vehicle"]) if row.get("vehicle") else None,
                rig_path=str(base / str(rig)) if rig and not os.path.isabs(str(rig)) else rig,  # type: ignore[arg-type]
                tags=tuple(str(t) for t in tags),
                source=str(path),
            )
        )
    return jobs


def log_metadata_vehicle(path: Path) -> str | None:
    """The vehicle id recorded in the log itself, if any (cheap: index/metadata only)."""
    try:
        if path.is_dir():
            meta = parse_text(read_text(path / "metadata.yaml"), "YAML")
            info = (meta or {}).get("rosbag2_bagfile_information", {})
            custom = info.get("custom_data") or {}
            return next((str(custom[k]) for k in VEHICLE_KEYS if custom.get(k)), None)
        if path.suffix == ".mcap":
            from mcap.reader import make_reader

            with path.open("rb") as handle:
                for record in make_reader(handle).iter_metadata():
                    value = next(
                        (record.metadata[k] for k in VEHICLE_KEYS if record.metadata.get(k)), None
                    )
                    if value:
                        return str(value)
    except Exception:  # metadata is optional: a damaged log is reported by its audit
        return None
    return None


def _where_vehicle_comes_from(path: str) -> str:
    """What this kind of log can say about its vehicle (for the no-vehicle warning)."""
    if is_url(path):
        return "a remote log's own metadata is not read"
    local = Path(path)
    if local.is_dir():
        return "its metadata.yaml has no custom_data vehicle_id/vehicle"
    if local.suffix == ".bag":
        return "a ROS 1 bag records none (it has no metadata record)"
    if local.suffix == ".db3":
        return "a bare .db3 file records none (no metadata.yaml beside it)"
    return "it has no MCAP metadata record with vehicle_id/vehicle"


def no_vehicle_warning(path: str, policy: Policy) -> str:
    """The warning for a log left without a vehicle id: why, and the ways to give one."""
    pattern = (
        f"the policy's vehicle_pattern '{policy.vehicle_pattern}' does not match its path"
        if policy.vehicle_pattern
        else "the policy has no vehicle_pattern"
    )
    return (
        f"{public_url(path) if is_url(path) else path}: no vehicle id "
        f"({_where_vehicle_comes_from(path)}; {pattern}): give it in a manifest (CSV/JSONL "
        "column 'vehicle') or a vehicle_pattern with a (?P<vehicle>...) group that matches "
        "the path; judged with the default checks and rig"
    )


def discover(inputs: list[str], policy: Policy) -> Discovery:
    """Every log named by `inputs`, deduplicated, with vehicle and rig resolved."""
    found = Discovery()
    raw: list[LogJob] = []
    for item in inputs:
        if is_url(item):
            urls = list_logs(item)
            if not urls:
                found.problems.append(f"{public_url(item)}: matches no log")
            raw.extend(LogJob(path=url) for url in urls)
            continue
        paths = _expand(item)
        if paths is None:
            raw.extend(read_manifest(Path(item)))
            continue
        if not paths:
            found.problems.append(f"{item}: matches no log")
        raw.extend(LogJob(path=str(p)) for p in paths)
    pattern = re.compile(policy.vehicle_pattern) if policy.vehicle_pattern else None
    remote_rigs = _remote_rigs(
        list(dict.fromkeys(j.path for j in raw if j.rig_path is None and is_url(j.path))), found
    )
    seen: set[str] = set()
    for job in raw:
        remote = is_url(job.path)
        key = public_url(job.path) if remote else os.path.abspath(job.path)
        if key in seen:
            continue
        seen.add(key)
        path = Path(job.path)
        vehicle = job.vehicle or (None if remote else log_metadata_vehicle(path))
        if vehicle is None and pattern is not None:
            match = pattern.search(path.as_posix())
            vehicle = match.group("vehicle") if match else None
        if vehicle is None and policy.uses_vehicles():
            found.warnings.append(no_vehicle_warning(job.path, policy))
        rig = job.rig_path
        if rig is None and remote:
            rig = remote_rigs.get(job.path)
        if rig is None and not remote:
            beside = local_rig_beside(path)
            rig = None if beside is None else str(beside)
        if rig is None and vehicle is not None:
            rig = policy.rigs.get(vehicle)
        rig = rig or policy.default_rig
        found.jobs.append(
            LogJob(path=job.path, vehicle=vehicle, rig_path=rig, tags=job.tags, source=job.source)
        )
    found.jobs.sort(key=lambda j: j.path)
    found.warnings.sort()
    return found


def fingerprint(path: str | Path) -> str:
    """A content fingerprint read cheaply: size, and 1 MiB at the head, the tail and
    evenly spaced offsets of each file (a bag folder: every file, by relative name).

    MCAP and ROS bag tails hold the index (chunk offsets, CRCs, counts), so any rewrite
    changes them; hashing every byte of a fleet's terabytes would cost more than the
    audit. Raises LogOpenError when nothing is there.
    """
    if isinstance(path, str) and is_url(path):
        return remote_fingerprint(path)
    path = Path(path)
    digest = hashlib.blake2b(digest_size=16)
    if path.is_dir():
        files = sorted(p for p in path.rglob("*") if p.is_file())
    elif path.is_file():
        files = [path]
    else:
        raise LogOpenError(f"{path}: no such log")
    for file in files:
        size = file.stat().st_size
        digest.update(f"{file.relative_to(path) if path.is_dir() else ''}:{size}".encode())
        with file.open("rb") as handle:
            if size <= SAMPLE_BYTES * (SAMPLE_COUNT + 2):
                digest.update(handle.read())
                continue
            step = (size - SAMPLE_BYTES) // (SAMPLE_COUNT + 1)
            for index in range(SAMPLE_COUNT + 2):
                handle.seek(min(index * step, size - SAMPLE_BYTES))
                digest.update(handle.read(SAMPLE_BYTES))
    return digest.hexdigest()


RIG_LOOKUPS_IN_FLIGHT = 16
"""Remote logs whose rig beside them is asked for at once (one small request each)."""


def _remote_rigs(log_urls: list[str], found: Discovery) -> dict[str, str]:
    """The URL of the rig beside each remote log that has one, as beside a local log (one
    request each, `RIG_LOOKUPS_IN_FLIGHT` at once); a refusal is a warning (the log is
    judged with the policy's rig), a failing server a problem."""
    from concurrent.futures import ThreadPoolExecutor

    def look(url: str) -> Sidecar | LogReadError:
        try:
            return rig_sidecar(url)
        except LogReadError as exc:
            return exc

    if not log_urls:
        return {}
    with ThreadPoolExecutor(min(RIG_LOOKUPS_IN_FLIGHT, len(log_urls))) as pool:
        answers = list(pool.map(look, log_urls))
    rigs: dict[str, str] = {}
    for url, answer in zip(log_urls, answers, strict=True):
        if isinstance(answer, LogReadError):
            found.problems.append(f"{answer}: the log is judged without its rig")
        elif answer.refused is not None:
            found.warnings.append(
                f"{answer.name}: cannot read the rig beside the log ({answer.refused}); "
                "judged with the manifest's or the policy's rig"
            )
        elif answer.data is not None:
            rigs[url] = answer.url
    return rigs


def file_fingerprint(path: str | Path | None) -> str | None:
    """Hash of a small config file's bytes (rig, local or by URL), None when there is none."""
    if path is None:
        return None
    try:
        if isinstance(path, str) and is_url(path):
            from syncaudit.remote.sidecar import read_small

            data = read_small(path).data
            return None if data is None else hashlib.sha256(data).hexdigest()[:16]
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]
    except (OSError, LogReadError):
        return None
