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

from syncaudit.columns.audit_result import SCHEMA_VERSION, AuditedLog
from syncaudit.columns.frame_table import FRAME_TABLE_DTYPES
from syncaudit.errors import OutputError

if TYPE_CHECKING:
    import pandas as pd

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


def _metadata(result: AuditedLog, table: str) -> dict[bytes, bytes]:
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


FRAME_DTYPES: dict[str, str] = FRAME_TABLE_DTYPES
"""Every column of `AuditResult.frames()` with its type: an audit without cameras (whose
`frames()` has no columns) still writes them all, with zero rows (a test keeps this equal
to a real audit's table)."""

UNPAIRED_REASONS = (
    "error beyond a quarter revolution",
    "no LiDAR revolution",
    "no exposure metadata",
)
"""Why a frame is not paired (`CameraSync.unpaired` keys): a count column each, always."""

_SUMMARY_HEAD: dict[str, str] = {
    "camera": "string",
    "theta_deg": "Float64",
    "omega_deg_s": "Float64",
    "t_rotate_us": "Float64",
    "packet_phase_us": "Float64",
    "packet_phase_source": "string",
    "trigger_pairing": "string",
    "t5_mean_us": "Float64",
    "delay_applied_us": "Float64",
    "delay_recommended_us": "Float64",
    "delay_from_error_us": "Float64",
    "frames_total": "int64",
    "frames_paired": "int64",
    "error_signed_mean_us": "Float64",
    "error_mean_us": "Float64",
    "error_var_us2": "Float64",
    "error_p99_us": "Float64",
    "error_max_us": "Float64",
    "rolling_mean_max_us": "Float64",
    "rolling_var_max_us2": "Float64",
    "mean_threshold_exceeded": "bool",
    "var_threshold_exceeded": "bool",
    "needs_correction": "bool",
    "judged": "bool",
    "not_judged_reason": "string",
    "optional": "bool",
    "verdict": "string",
    "azimuth_deg": "Float64",
    "azimuth_source": "string",
}
_LATENCY_STATS = {"status": "string", "mean_us": "Float64", "p50_us": "Float64"}
_LATENCY_STATS |= {"p99_us": "Float64", "count": "Int64"}
_CORRECTED: dict[str, str] = {
    "adjustments": "Int64",
    "final_delay_us": "Float64",
    "error_mean_us": "Float64",
    "error_var_us2": "Float64",
    "error_signed_mean_us": "Float64",
    "settled_error_mean_us": "Float64",
    "settled_error_var_us2": "Float64",
}


def summary_dtypes(unpaired: tuple[str, ...] = UNPAIRED_REASONS) -> dict[str, str]:
    """The per-camera summary's columns and types (the same with or without cameras)."""
    dtypes = dict(_SUMMARY_HEAD)
    for name in ("t1", "t2", "t3", "t4"):
        dtypes |= {f"{name}_{stat}": kind for stat, kind in _LATENCY_STATS.items()}
    dtypes |= {f"unpaired_{reason}": "int64" for reason in unpaired}
    dtypes |= {f"corrected_{key}": kind for key, kind in _CORRECTED.items()}
    dtypes["warnings"] = "string"
    return dtypes


def typed_frames(result: AuditedLog) -> pd.DataFrame:
    """`result.frames()` with every column of `FRAME_DTYPES` typed (zero rows without cameras)."""
    import pandas as pd

    frames = result.frames()
    if not len(frames.columns):
        return pd.DataFrame({c: pd.Series([], dtype=t) for c, t in FRAME_DTYPES.items()})
    return frames.astype({c: t for c, t in FRAME_DTYPES.items() if c in frames.columns})


def camera_summary(result: AuditedLog) -> pd.DataFrame:
    """One row per camera: verdict, Eq. 1-6 figures, latencies, replay (µs as the JSON).

    Typed by `summary_dtypes`, so a log without cameras gets the same columns, no rows.
    """
    import pandas as pd

    extra = {k for c in result.cameras for k in c.sync.unpaired} - set(UNPAIRED_REASONS)
    dtypes = summary_dtypes((*UNPAIRED_REASONS, *sorted(extra)))
    rows: list[dict[str, Any]] = []
    for cam in result.cameras:
        d = cam.to_dict()
        row: dict[str, Any] = {k: d.get(k) for k in _SUMMARY_HEAD}
        for name in ("t1", "t2", "t3", "t4"):
            lat = d["latencies"].get(name, {})
            row |= {f"{name}_{stat}": lat.get(stat) for stat in _LATENCY_STATS}
        for column in dtypes:
            if column.startswith("unpaired_"):
                row[column] = int(d["unpaired"].get(column[len("unpaired_") :], 0))
        corrected = d["corrected"] or {}
        row |= {f"corrected_{key}": corrected.get(key) for key in _CORRECTED}
        row["warnings"] = "; ".join(d["warnings"])
        rows.append(row)
    frame = pd.DataFrame(rows, columns=list(dtypes))
    # Missing numbers (None) become nulls of their column's type, never an object column.
    return frame.astype(dtypes)


def _table_bytes(frame: pd.DataFrame, metadata: dict[bytes, bytes]) -> bytes:
    pa = _pyarrow()
    import pyarrow.parquet as pq

    table = pa.Table.from_pandas(frame, preserve_index=False)
    table = table.replace_schema_metadata({**(table.schema.metadata or {}), **metadata})
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="zstd")
    data: bytes = sink.getvalue().to_pybytes()
    return data


def frames_parquet(result: AuditedLog) -> bytes:
    """The per-frame table (every column of `frames()`) as Parquet bytes."""
    _pyarrow()
    return _table_bytes(typed_frames(result), _metadata(result, "frames"))


def cameras_parquet(result: AuditedLog) -> bytes:
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


def write_parquet(result: AuditedLog, path: str | Path) -> tuple[Path, Path]:
    """Write both tables (frames at `path`, summary at `cameras_path(path)`); their paths.

    Both are rendered before either is written, so a failure leaves neither half-done.
    """
    frames_file, cameras_file = Path(path), cameras_path(path)
    frames, cameras = frames_parquet(result), cameras_parquet(result)
    _write_bytes_atomic(frames_file, frames)
    _write_bytes_atomic(cameras_file, cameras)
    return frames_file, cameras_file
