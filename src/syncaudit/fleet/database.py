"""The results database: DuckDB tables of every judged log (schema in `fleet.schema`).

DuckDB allows one process to open a database file for writing at a time (others get an
IOException). Every access here is short and inside an exclusive lock (flock) on the
database's folder: no lock file is made, so none is left after a run, an interruption or a
killed process (the kernel drops the lock with the last descriptor). DuckDB's own lock
error (another program holding the file, e.g. a user's `duckdb` shell) is retried with
backoff. Concurrent `gate` runs therefore take turns per
batch of rows; each batch is one transaction, so a row set is all there or not at all.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import time
from collections.abc import Iterable, Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from syncaudit.errors import OutputError
from syncaudit.fleet.checks import CheckResult, drop_rate
from syncaudit.fleet.inputs import LogJob
from syncaudit.fleet.record import JudgedLog
from syncaudit.fleet.schema import SCHEMA_VERSION, columns, create_statements

LOCK_TIMEOUT_S = 600.0


def _ts(ns: int | None) -> datetime | None:
    if ns is None:
        return None
    return datetime.fromtimestamp(ns / 1e9, tz=UTC).replace(tzinfo=None)


class ResultsDB:
    """A DuckDB results file shared safely between processes."""

    def __init__(self, path: str | Path, *, lock_timeout_s: float = LOCK_TIMEOUT_S) -> None:
        self.path = Path(path)
        self.lock_timeout_s = lock_timeout_s

    @contextlib.contextmanager
    def connect(self, *, read_only: bool = False) -> Iterator[Any]:
        """An open connection, held under the inter-process lock for as short as possible."""
        import duckdb

        if read_only and not self.path.exists():
            raise OutputError(f"{self.path}: no such results database")
        folder = self.path.parent
        try:
            lock_fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        except OSError as exc:
            raise OutputError(
                f"{folder}: cannot lock the results database ({exc.strerror})"
            ) from exc
        try:
            self._lock(lock_fd, folder)
            try:
                con = self._open(duckdb, read_only)
                try:
                    if not read_only:
                        for statement in create_statements():
                            con.execute(statement)
                    self._check_version(con)
                    yield con
                except duckdb.Error as exc:
                    first = str(exc).splitlines()[0]
                    raise OutputError(f"{self.path}: results database error: {first}") from exc
                finally:
                    con.close()
            finally:
                fcntl.flock(lock_fd, fcntl.LOCK_UN)
        finally:
            os.close(lock_fd)

    def _check_version(self, con: Any) -> None:
        """Refuse a database of another schema version (no silent mixing of layouts)."""
        row = con.execute("SELECT value FROM meta WHERE key = 'schema_version'").fetchone()
        if row is None or row[0] != str(SCHEMA_VERSION):
            found = "none" if row is None else row[0]
            raise OutputError(
                f"{self.path}: results database schema version {found}, this syncaudit "
                f"writes {SCHEMA_VERSION}: use a new --db file"
            )

    def _lock(self, lock_fd: int, folder: Path) -> None:
        deadline = time.monotonic() + self.lock_timeout_s
        delay = 0.01
        while True:
            try:
                fcntl.flock(lock_fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                return
            except BlockingIOError:
                if time.monotonic() > deadline:
                    raise OutputError(
                        f"{self.path}: still locked by another run after {self.lock_timeout_s:g} s "
                        f"(the lock is held on its folder {folder})"
                    ) from None
                time.sleep(delay)
                delay = min(delay * 2, 0.5)

    def _open(self, duckdb: Any, read_only: bool) -> Any:
        deadline = time.monotonic() + self.lock_timeout_s
        delay = 0.05
        while True:
            try:
                return duckdb.connect(str(self.path), read_only=read_only)
            except duckdb.IOException as exc:
                if "lock" not in str(exc).lower() or time.monotonic() > deadline:
                    raise OutputError(
                        f"{self.path}: cannot open the results database ({exc})"
                    ) from exc
                time.sleep(delay)
                delay = min(delay * 2, 1.0)
            except duckdb.Error as exc:
                raise OutputError(f"{self.path}: not a usable DuckDB database ({exc})") from exc

    def known(self, keys: Iterable[str]) -> dict[str, JudgedLog]:
        """Earlier verdicts stored under these keys (with their checks), by key."""
        wanted = sorted(set(keys))
        if not wanted or not self.path.exists():
            return {}
        with self.connect() as con:
            con.execute("CREATE TEMP TABLE wanted (log_key VARCHAR)")
            con.executemany("INSERT INTO wanted VALUES (?)", [(k,) for k in wanted])
            rows = con.execute("SELECT l.* FROM logs l JOIN wanted w USING (log_key)").fetchall()
            names = [d[0] for d in con.description]
            checks = con.execute(
                "SELECT c.* FROM checks c JOIN wanted w USING (log_key) "
                'ORDER BY scope, subject, "check"'
            ).fetchall()
            check_names = [d[0] for d in con.description]
        by_key: dict[str, list[CheckResult]] = {}
        for row in checks:
            item = dict(zip(check_names, row, strict=True))
            by_key.setdefault(item.pop("log_key"), []).append(CheckResult(**item))
        out = {}
        for row in rows:
            item = dict(zip(names, row, strict=True))
            job = LogJob(
                path=item["path"],
                vehicle=item["vehicle"],
                tags=tuple(json.loads(item["tags"] or "[]")),
            )
            out[item["log_key"]] = JudgedLog(
                job=job,
                key=item["log_key"],
                fingerprint=item["fingerprint"],
                rig_fingerprint=item["rig_fingerprint"],
                policy_fingerprint=item["policy_fingerprint"],
                tool_version=item["tool_version"],
                verdict=item["verdict"],
                checks=by_key.get(item["log_key"], []),
                error=item["error"],
                error_code=item["error_code"],
                attempts=item["attempts"] or 1,
                skipped=True,
                report=item["report"],
                health=json.loads(item["health"]) if item.get("health") else None,
                advice=json.loads(item["advice"]) if item.get("advice") else {},
            )
        return out

    def write(self, logs: list[JudgedLog]) -> None:
        """Store verdicts (replacing any with the same key) in one transaction."""
        if not logs:
            return
        now = datetime.now(UTC).replace(tzinfo=None)
        rows: dict[str, list[tuple[Any, ...]]] = {
            t: [] for t in ("logs", "cameras", "lidars", "checks")
        }
        for log in logs:
            rows["logs"].append(_log_row(log, now))
            rows["checks"].extend(
                (
                    log.key,
                    c.scope,
                    c.subject,
                    c.check,
                    c.value,
                    c.limit,
                    c.unit,
                    c.severity,
                    c.passed,
                    c.message,
                    c.limit_min,
                    c.limit_max,
                )
                for c in log.checks
            )
            if log.audit is not None:
                rows["cameras"].extend(_camera_row(log.key, cam) for cam in log.audit["cameras"])
                rows["lidars"].append(_lidar_row(log.key, log.audit["lidar"]))
        keys = [(log.key,) for log in logs]
        with self.connect() as con:
            con.execute("BEGIN TRANSACTION")
            try:
                for table, table_rows in rows.items():
                    con.executemany(f"DELETE FROM {table} WHERE log_key = ?", keys)
                    if table_rows:
                        names = columns(table)
                        marks = ", ".join("?" for _ in names)
                        con.executemany(f"INSERT INTO {table} VALUES ({marks})", table_rows)
                con.execute("COMMIT")
            except BaseException:
                con.execute("ROLLBACK")
                raise


def _log_row(log: JudgedLog, now: datetime) -> tuple[Any, ...]:
    audit = log.audit or {}
    return (
        log.key,
        log.fingerprint,
        log.path,
        log.job.vehicle,
        _ts(log.start_ns),
        audit.get("duration_s", log.duration_s),
        audit.get("container", log.container),
        log.tool_version,
        log.rig_fingerprint,
        log.policy_fingerprint,
        log.verdict,
        log.error,
        log.error_code,
        json.dumps(list(log.job.tags)),
        log.attempts,
        log.elapsed_s,
        log.report,
        now,
        None if log.health is None else bool(log.health.get("intact")),
        None if log.health is None else json.dumps(log.health, sort_keys=True),
        json.dumps(log.advice, sort_keys=True) if log.advice else None,
    )


def _camera_row(key: str, cam: dict[str, Any]) -> tuple[Any, ...]:
    lat = cam.get("latencies") or {}
    corrected = cam.get("corrected") or {}
    values: list[Any] = [
        key,
        cam["camera"],
        cam.get("theta_deg"),
        cam.get("omega_deg_s"),
        cam.get("azimuth_deg"),
        cam.get("azimuth_source"),
        cam.get("t_rotate_us"),
        cam.get("packet_phase_us"),
    ]
    for name in ("t1", "t2", "t3", "t4"):
        stats = lat.get(name) or {}
        values += [
            stats.get("mean_us"),
            stats.get("p50_us"),
            stats.get("p99_us"),
            stats.get("status"),
        ]
    values += [
        cam.get(name)
        for name in (
            "t5_mean_us",
            "delay_applied_us",
            "delay_recommended_us",
            "delay_from_error_us",
            "frames_total",
            "frames_paired",
            "error_signed_mean_us",
            "error_mean_us",
            "error_var_us2",
            "error_p99_us",
            "error_max_us",
            "rolling_mean_max_us",
            "rolling_var_max_us2",
            "mean_threshold_exceeded",
            "var_threshold_exceeded",
            "needs_correction",
        )
    ]
    values += [
        corrected.get("final_delay_us"),
        corrected.get("error_mean_us"),
        corrected.get("error_var_us2"),
    ]
    return tuple(values)


def _lidar_row(key: str, lidar: dict[str, Any]) -> tuple[Any, ...]:
    return (
        key,
        lidar.get("topic"),
        lidar.get("vendor"),
        lidar.get("model"),
        lidar.get("scans"),
        lidar.get("packets"),
        lidar.get("revolutions"),
        lidar.get("rpm"),
        lidar.get("packets_per_revolution"),
        lidar.get("dropped_packets"),
        drop_rate(lidar),
        lidar.get("dual_return"),
        lidar.get("clock_offset_s"),
        lidar.get("clock_synchronised"),
        lidar.get("t1_p50_us"),
        lidar.get("t1_p99_us"),
    )
