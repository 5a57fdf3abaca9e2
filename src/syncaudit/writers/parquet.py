"""`audit --parquet F`: the per-frame table and the per-camera summary as Parquet.

Two files, because a Parquet file holds one table and every reader (pandas, polars,
DuckDB `FROM 'F'`) opens one file as one table: `F` holds every column of
`AuditResult.frames()` (stamps int64 nanoseconds, nullable where the log lacks them,
booleans and strings typed), `cameras_path(F)` (`F` with `.cameras.parquet`) one row per
camera with its verdict and statistics (microseconds, as the JSON). Both carry the log,
the schema version and the thresholds as file metadata (`syncaudit` key, JSON).
pyarrow is an optional extra (`syncaudit[parquet]`): about 170 MB installed, which most
users, who read the JSON or the CSV, never need.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

from syncaudit.errors import OutputError

if TYPE_CHECKING:
    import pandas as pd

    from syncaudit.audit import AuditResult

INSTALL_HINT = "--parquet needs pyarrow: pip install 'syncaudit[parquet]'"


def cameras_path(frames_path: str | Path) -> Path:
    """Where the per-camera summary goes: `F.parquet` -> `F.cameras.parquet`."""
    path = Path(frames_path)
    stem = path.name[: -len(".parquet")] if path.name.endswith(".parquet") else path.name
    return path.with_name(f"{stem}.cameras.parquet")


def require_pyarrow() -> None:
    """Fail before any work when pyarrow is not installed (OutputError, exit 8)."""
    _pyarrow()


def _pyarrow() -> Any:
    try:
        import pyarrow as pa
        import pyarrow.parquet
    except ImportError as exc:
        raise OutputError(INSTALL_HINT) from exc
    return pa


def _metadata(result: AuditResult, table: str) -> dict[bytes, bytes]:
    from syncaudit.audit import SCHEMA_VERSION

    meta = {
        "table": table,
        "schema_version": SCHEMA_VERSION,
        "log": result.path,
        "verdict": result.verdict,
        "start_ns": result.start_ns,
        "clock_offset_ns": result.clock_offset_ns,
        "thresholds": result.rig.thresholds.model_dump(),
        "window_frames": result.rig.analysis.window_frames,
    }
    return {b"syncaudit": json.dumps(meta).encode()}


def camera_summary(result: AuditResult) -> pd.DataFrame:
    """One row per camera: verdict, Eq. 1-6 figures, latencies, replay (µs as the JSON)."""
    import pandas as pd

    rows: list[dict[str, Any]] = []
    unpaired_keys = sorted({k for c in result.cameras for k in c.sync.unpaired})
    for cam in result.cameras:
        d = cam.to_dict()
        row: dict[str, Any] = {}
        for key, value in d.items():
            if key in ("latencies", "unpaired", "corrected", "warnings"):
                continue
            row[key] = value
        for name in ("t1", "t2", "t3", "t4"):
            lat = d["latencies"].get(name, {})
            row[f"{name}_status"] = lat.get("status")
            for stat in ("mean_us", "p50_us", "p99_us", "count"):
                row[f"{name}_{stat}"] = lat.get(stat)
        for key in unpaired_keys:
            row[f"unpaired_{key}"] = int(d["unpaired"].get(key, 0))
        corrected = d["corrected"] or {}
        for key in (
            "adjustments",
            "final_delay_us",
            "error_mean_us",
            "error_var_us2",
            "error_signed_mean_us",
            "settled_error_mean_us",
            "settled_error_var_us2",
        ):
            row[f"corrected_{key}"] = corrected.get(key)
        row["warnings"] = "; ".join(d["warnings"])
        rows.append(row)
    frame = pd.DataFrame(rows)
    for column in frame.columns:
        if column.startswith("unpaired_") or column in ("frames_total", "frames_paired"):
            frame[column] = frame[column].astype("int64")
        elif column.endswith("_count") or column == "corrected_adjustments":
            frame[column] = frame[column].astype("Int64")
        elif frame[column].dtype == object and column not in _BOOL_COLUMNS:
            if all(isinstance(v, str) or v is None for v in frame[column]):
                frame[column] = frame[column].astype("string")
            else:
                frame[column] = frame[column].astype("Float64")
    return frame


_BOOL_COLUMNS = frozenset(
    {"mean_threshold_exceeded", "var_threshold_exceeded", "needs_correction", "judged", "optional"}
)


def _table_bytes(frame: pd.DataFrame, metadata: dict[bytes, bytes]) -> bytes:
    pa = _pyarrow()
    import pyarrow.parquet as pq

    table = pa.Table.from_pandas(frame, preserve_index=False)
    table = table.replace_schema_metadata({**(table.schema.metadata or {}), **metadata})
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="zstd")
    data: bytes = sink.getvalue().to_pybytes()
    return data


def frames_parquet(result: AuditResult) -> bytes:
    """The per-frame table (every column of `frames()`) as Parquet bytes."""
    _pyarrow()
    return _table_bytes(result.frames(), _metadata(result, "frames"))


def cameras_parquet(result: AuditResult) -> bytes:
    """The per-camera summary as Parquet bytes."""
    _pyarrow()
    return _table_bytes(camera_summary(result), _metadata(result, "cameras"))


def _write_bytes_atomic(path: Path, data: bytes) -> None:
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent or ".")
    except OSError as exc:
        raise OutputError(f"{path}: cannot write ({exc.strerror or exc})") from exc
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
        mask = os.umask(0)
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)
        os.replace(tmp, path)
    except OSError as exc:
        Path(tmp).unlink(missing_ok=True)
        raise OutputError(f"{path}: cannot write ({exc.strerror or exc})") from exc
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_parquet(result: AuditResult, path: str | Path) -> tuple[Path, Path]:
    """Write both tables (frames at `path`, summary at `cameras_path(path)`); their paths.

    Both are rendered before either is written, so a failure leaves neither half-done.
    """
    frames_file, cameras_file = Path(path), cameras_path(path)
    frames, cameras = frames_parquet(result), cameras_parquet(result)
    _write_bytes_atomic(frames_file, frames)
    _write_bytes_atomic(cameras_file, cameras)
    return frames_file, cameras_file
