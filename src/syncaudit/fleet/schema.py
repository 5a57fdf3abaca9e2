"""The results database's schema (DuckDB): one documented place, used by writer and reports.

Tables (one row per judged log in `logs`, keyed by `log_key`):

- `logs`: `log_key` (hash of fingerprint, path, tool version, rig and policy fingerprints),
  `fingerprint` (content, see `inputs.fingerprint`), `path` (or URL without its query
  string), `vehicle`, `start_time` (first message, UTC), `duration_s`, `container`,
  `tool_version`, `rig_fingerprint`, `policy_fingerprint`, `verdict` (pass, warn, fail,
  error), `error` (one line, for error rows), `error_code` (the exit code the error
  carries), `tags` (JSON list), `attempts`, `elapsed_s`, `report` (HTML report path, if
  written), `judged_at` (UTC, when the row was written), `intact` (false: the file was cut
  off, lost damaged messages or its index; null for error rows) and `health` (the audit's
  `health` record as JSON: `truncated`, `cut_at_byte`, `damaged_messages` per topic, ...)
  and `advice` (each camera's `recommendation` as JSON, by camera name; null for error rows).
- `cameras`: every statistic of the audit per camera (times in microseconds).
- `lidars`: the triggering LiDAR's statistics.
- `checks`: one row per check: `scope`, `subject`, `check`, `value`, `limit`, `unit`,
  `severity`, `passed`, `message`, `limit_min`, `limit_max` (numeric bounds, null where open).
"""

from __future__ import annotations

SCHEMA_VERSION = 1

TABLES: dict[str, str] = {
    "logs": """
        log_key VARCHAR NOT NULL,
        fingerprint VARCHAR NOT NULL,
        path VARCHAR NOT NULL,
        vehicle VARCHAR,
        start_time TIMESTAMP,
        duration_s DOUBLE,
        container VARCHAR,
        tool_version VARCHAR NOT NULL,
        rig_fingerprint VARCHAR,
        policy_fingerprint VARCHAR NOT NULL,
        verdict VARCHAR NOT NULL,
        error VARCHAR,
        error_code INTEGER,
        tags VARCHAR,
        attempts INTEGER,
        elapsed_s DOUBLE,
        report VARCHAR,
        judged_at TIMESTAMP NOT NULL,
        intact BOOLEAN,
        health VARCHAR,
        advice VARCHAR
    """,
    "cameras": """
        log_key VARCHAR NOT NULL,
        camera VARCHAR NOT NULL,
        theta_deg DOUBLE,
        omega_deg_s DOUBLE,
        azimuth_deg DOUBLE,
        azimuth_source VARCHAR,
        t_rotate_us DOUBLE,
        packet_phase_us DOUBLE,
        t1_mean_us DOUBLE, t1_p50_us DOUBLE, t1_p99_us DOUBLE, t1_status VARCHAR,
        t2_mean_us DOUBLE, t2_p50_us DOUBLE, t2_p99_us DOUBLE, t2_status VARCHAR,
        t3_mean_us DOUBLE, t3_p50_us DOUBLE, t3_p99_us DOUBLE, t3_status VARCHAR,
        t4_mean_us DOUBLE, t4_p50_us DOUBLE, t4_p99_us DOUBLE, t4_status VARCHAR,
        t5_mean_us DOUBLE,
        delay_applied_us DOUBLE,
        delay_recommended_us DOUBLE,
        delay_from_error_us DOUBLE,
        frames_total INTEGER,
        frames_paired INTEGER,
        error_signed_mean_us DOUBLE,
        error_mean_us DOUBLE,
        error_var_us2 DOUBLE,
        error_p99_us DOUBLE,
        error_max_us DOUBLE,
        rolling_mean_max_us DOUBLE,
        rolling_var_max_us2 DOUBLE,
        mean_threshold_exceeded BOOLEAN,
        var_threshold_exceeded BOOLEAN,
        needs_correction BOOLEAN,
        corrected_final_delay_us DOUBLE,
        corrected_error_mean_us DOUBLE,
        corrected_error_var_us2 DOUBLE
    """,
    "lidars": """
        log_key VARCHAR NOT NULL,
        topic VARCHAR NOT NULL,
        vendor VARCHAR,
        model VARCHAR,
        scans INTEGER,
        packets BIGINT,
        revolutions BIGINT,
        rpm DOUBLE,
        packets_per_revolution DOUBLE,
        dropped_packets BIGINT,
        drop_rate DOUBLE,
        dual_return BOOLEAN,
        clock_offset_s DOUBLE,
        clock_synchronised BOOLEAN,
        t1_p50_us DOUBLE,
        t1_p99_us DOUBLE
    """,
    "checks": """
        log_key VARCHAR NOT NULL,
        scope VARCHAR NOT NULL,
        subject VARCHAR NOT NULL,
        "check" VARCHAR NOT NULL,
        value DOUBLE,
        "limit" VARCHAR,
        unit VARCHAR,
        severity VARCHAR NOT NULL,
        passed BOOLEAN NOT NULL,
        message VARCHAR,
        limit_min DOUBLE,
        limit_max DOUBLE
    """,
}


KEYS: dict[str, tuple[str, ...]] = {
    "logs": ("log_key",),
    "cameras": ("log_key", "camera"),
    "lidars": ("log_key", "topic"),
    "checks": ("log_key", "scope", "subject", "check"),
}


ADDED_COLUMNS: tuple[tuple[str, str], ...] = (
    ("intact", "BOOLEAN"),
    ("health", "VARCHAR"),
    ("advice", "VARCHAR"),
)
"""Columns of `logs` newer than schema version 1's first layout (added to older files)."""


def _column_defs(table: str) -> list[tuple[str, str]]:
    """(name, SQL type and constraints) of each column of a table, in order."""
    defs = []
    for line in TABLES[table].replace(", t", ",\n t").splitlines():
        for part in line.split(","):
            words = part.split()
            if words and words[0] != "PRIMARY":
                defs.append((words[0].strip('"'), " ".join(words[1:])))
    return defs


def columns(table: str) -> list[str]:
    """Column names of a table, in order."""
    return [name for name, _ in _column_defs(table)]


def create_statements() -> list[str]:
    """CREATE TABLE IF NOT EXISTS for every table, plus the schema version."""
    statements = []
    for table in TABLES:
        cols = ", ".join(f'"{name}" {kind}' for name, kind in _column_defs(table))
        keys = ", ".join(f'"{k}"' for k in KEYS[table])
        statements.append(f"CREATE TABLE IF NOT EXISTS {table} ({cols}, PRIMARY KEY ({keys}))")
    # Added after the first databases were written: appended, so positional inserts agree.
    for name, kind in ADDED_COLUMNS:
        statements.append(f'ALTER TABLE logs ADD COLUMN IF NOT EXISTS "{name}" {kind}')
    statements.append("CREATE TABLE IF NOT EXISTS meta (key VARCHAR PRIMARY KEY, value VARCHAR)")
    statements.append(f"INSERT OR IGNORE INTO meta VALUES ('schema_version', '{SCHEMA_VERSION}')")
    return statements
