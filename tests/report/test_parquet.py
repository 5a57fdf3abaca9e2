"""`audit --parquet`: the per-frame table and per-camera summary, read back by three readers."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import duckdb
import numpy as np
import pandas as pd
import polars as pl
import pyarrow.parquet as pq
import pytest
import yaml
from typer.testing import CliRunner

from syncaudit.audit.run import AuditResult
from syncaudit.cli import app
from syncaudit.writers.parquet import cameras_path, write_parquet

THREE_CAMERAS = Path(__file__).resolve().parents[2] / "sample_logs" / "vlp16_three_cameras.mcap"
STAMPS = (
    "exposure_start_ns",
    "exposure_duration_ns",
    "t_l_ns",
    "t_estimated_ns",
    "revolution_start_ns",
    "header_stamp_ns",
)


def test_cameras_path() -> None:
    assert cameras_path("out/run.parquet") == Path("out/run.cameras.parquet")
    assert cameras_path("frames") == Path("frames.cameras.parquet")


def test_frames_round_trip_typed(audit: AuditResult, tmp_path: Path) -> None:
    frames_file, _ = write_parquet(audit, tmp_path / "a.parquet")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.cameras.parquet", "a.parquet"]
    expected = audit.frames()
    schema = pq.read_schema(frames_file)
    assert schema.names == list(expected.columns)
    for name in STAMPS:
        assert str(schema.field(name).type) == "int64", name
    assert str(schema.field("paired").type) == "bool"
    assert str(schema.field("camera").type) in ("string", "large_string")
    meta = json.loads(schema.metadata[b"syncaudit"])
    assert meta["table"] == "frames" and meta["log"] == audit.path
    assert meta["thresholds"]["error_mean_us"] == audit.rig.thresholds.error_mean_us
    # pandas: identical frame (nullable Int64 stamps, missing stay missing)
    back = pd.read_parquet(frames_file)
    pd.testing.assert_frame_equal(back, expected, check_dtype=False)
    for name in STAMPS:
        assert back[name].dtype == "Int64"
        assert back[name].isna().sum() == expected[name].isna().sum()
    # polars and DuckDB: same rows, same exact integers
    polar = pl.read_parquet(frames_file)
    assert polar.height == len(expected) and polar.schema["t_l_ns"] == pl.Int64
    first = expected["t_l_ns"].dropna().iloc[0]
    assert polar["t_l_ns"].drop_nulls()[0] == first
    rows = duckdb.sql(
        f"SELECT camera, count(*) AS n, sum(paired::INT) AS p, max(t_l_ns) AS last "
        f"FROM '{frames_file}' GROUP BY camera ORDER BY camera"
    ).fetchall()
    for camera, n, p, last in rows:
        own = expected[expected["camera"] == camera]
        assert n == len(own) and p == own["paired"].sum() and last == own["t_l_ns"].max()


def test_camera_summary(audit: AuditResult, tmp_path: Path) -> None:
    _, cameras_file = write_parquet(audit, tmp_path / "a.parquet")
    table = pd.read_parquet(cameras_file)
    assert list(table["camera"]) == [c.sync.camera for c in audit.cameras]
    for row, cam in zip(table.itertuples(), audit.cameras, strict=True):
        d = cam.to_dict()
        assert row.verdict == d["verdict"] and bool(row.needs_correction) is d["needs_correction"]
        assert np.isclose(row.error_mean_us, d["error_mean_us"])
        assert np.isclose(row.delay_recommended_us, d["delay_recommended_us"])
        assert np.isclose(row.t1_p99_us, d["latencies"]["t1"]["p99_us"])
        assert row.frames_paired == d["frames_paired"]
        assert row.corrected_adjustments == d["corrected"]["adjustments"]
    counts = duckdb.execute(
        f"SELECT count(*) FROM '{cameras_file}' WHERE verdict = 'fail'"
    ).fetchone()
    assert counts == (sum(c.sync.verdict == "fail" for c in audit.cameras),)


def test_without_pyarrow_parquet_stops_before_any_work(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # import fails as if not installed
    monkeypatch.setitem(sys.modules, "pyarrow.parquet", None)
    log = Path(__file__).resolve().parents[2] / "sample_logs" / "vlp16_three_cameras.mcap"
    result = CliRunner().invoke(
        app,
        [
            "audit",
            str(log),
            "--html",
            str(tmp_path / "r.html"),
            "--parquet",
            str(tmp_path / "f.parquet"),
        ],
    )
    assert result.exit_code == 64, result.output  # a missing extra: usage error (issue 24)
    assert "pip install 'syncaudit[parquet]'" in result.output
    assert list(tmp_path.iterdir()) == []


def _odd_rig(tmp_path: Path, case: str) -> Path:
    """The sample's rig without cameras, or with cameras whose exposures are not in the log."""
    rig = yaml.safe_load(Path(f"{THREE_CAMERAS}.rig.yaml").read_text())
    if case == "no cameras":
        rig["cameras"] = []
    else:
        for camera in rig["cameras"]:
            del camera["exposure_topic"]  # no t_l: no frame pairs
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(rig))
    return path


@pytest.mark.parametrize("case", ["no cameras", "no paired frames"])
def test_same_typed_schema_without_cameras_or_paired_frames(
    audit: AuditResult, tmp_path: Path, case: str
) -> None:
    full = write_parquet(audit, tmp_path / "full.parquet")
    odd = (tmp_path / "odd.parquet", tmp_path / "odd.cameras.parquet")
    run = CliRunner().invoke(
        app,
        [
            "audit",
            str(THREE_CAMERAS),
            "--rig",
            str(_odd_rig(tmp_path, case)),
            "--parquet",
            str(odd[0]),
        ],
    )
    assert run.exit_code == 0, run.output
    for whole, other in zip(full, odd, strict=True):
        # Same columns, same Arrow types, in the same order (the metadata differs: the verdict).
        assert pq.read_schema(other).remove_metadata() == pq.read_schema(whole).remove_metadata()
        back, reference = pd.read_parquet(other), pd.read_parquet(whole)
        assert list(back.columns) == list(reference.columns)
        assert back.dtypes.to_dict() == reference.dtypes.to_dict()
        described = "SELECT column_name, column_type FROM (DESCRIBE FROM '{}')"
        with duckdb.connect() as con:
            types = con.execute(described.format(other)).fetchall()
            assert types == con.execute(described.format(whole)).fetchall()
    frames, cameras = pd.read_parquet(odd[0]), pd.read_parquet(odd[1])
    if case == "no cameras":
        assert len(frames) == 0 and len(cameras) == 0
        with duckdb.connect() as con:
            assert con.execute(f"SELECT count(*) FROM '{odd[0]}'").fetchone() == (0,)
        assert len(frames.columns) == len(audit.frames().columns) == 25
        assert json.loads(pq.read_schema(odd[0]).metadata[b"syncaudit"])["verdict"] == "no cameras"
        assert "trigger_pairing" in pq.read_schema(odd[1]).names
    else:
        assert len(frames) == 297 and not frames["paired"].any()
        assert frames["t_l_ns"].isna().all() and frames["error_signed_ns"].isna().all()
        # Missing statistics are nulls of a number column, not strings.
        assert cameras["error_mean_us"].isna().all() and cameras["t5_mean_us"].isna().all()
        assert list(cameras["unpaired_no exposure metadata"]) == [99, 99, 99]
        query = f"SELECT count(*) FROM '{odd[1]}' WHERE error_mean_us IS NULL AND t1_mean_us > 0"
        with duckdb.connect() as con:
            assert con.execute(query).fetchone() == (3,)


def test_real_lidar_log_without_cameras(
    audit: AuditResult, tmp_path: Path, lidar_data: Path
) -> None:
    """A real VLP-16 recording (no cameras): the typed tables with zero rows, and a report."""
    log = lidar_data / "velodyne_vlp16" / "1673400471837873222"
    out = tmp_path / "vlp16.parquet"
    run = CliRunner().invoke(
        app, ["audit", str(log), "--parquet", str(out), "--html", str(tmp_path / "r.html")]
    )
    assert run.exit_code == 0, run.output
    full = write_parquet(audit, tmp_path / "full.parquet")
    for whole, other in zip(full, (out, cameras_path(out)), strict=True):
        assert pq.read_schema(other).remove_metadata() == pq.read_schema(whole).remove_metadata()
        assert pq.read_metadata(other).num_rows == 0
    page = (tmp_path / "r.html").read_text()
    assert "NO CAMERAS" in page and "less the median +1,531.183 s" in page
    assert 'data-kind="lidar-drops"' in page and "none in 4 revolutions" in page


def _pairing_case(tmp_path: Path, case: str) -> tuple[Path, Path]:
    """A log and its rig whose cameras pair frames with triggers by `case`'s method."""
    if case == "sequence number":  # the sample: per-camera topics, ROS 2 TriggerEvent counters
        return THREE_CAMERAS, Path(f"{THREE_CAMERAS}.rig.yaml")
    if case == "none":  # the sample without its trigger topics
        rig = yaml.safe_load(Path(f"{THREE_CAMERAS}.rig.yaml").read_text())
        for camera in rig["cameras"]:
            del camera["trigger_topic"]
        path = tmp_path / "rig.yaml"
        path.write_text(yaml.safe_dump(rig))
        return THREE_CAMERAS, path
    # Metadata on one topic the cameras share, in ROS 2 (no header.seq): paired by time.
    log = tmp_path / "shared.mcap"
    run = CliRunner().invoke(
        app,
        [
            *("simulate", "sync", str(log), "--shared-topics", "meta"),
            *("--exposure-messages", "flir_meta", "--duration", "2", "--seed", "3"),
        ],
    )
    assert run.exit_code == 0, run.output
    return log, Path(f"{log}.rig.yaml")


@pytest.mark.parametrize("case", ["sequence number", "time", "none"])
def test_trigger_pairing_column_equals_the_json(tmp_path: Path, case: str) -> None:
    """`trigger_pairing` of the per-camera summary: the JSON's, camera by camera."""
    log, rig = _pairing_case(tmp_path, case)
    json_out, parquet_out = tmp_path / "a.json", tmp_path / "a.parquet"
    run = CliRunner().invoke(
        app,
        [
            *("audit", str(log), "--rig", str(rig)),
            *("--json-out", str(json_out), "--parquet", str(parquet_out)),
        ],
    )
    assert run.exit_code == 0, run.output
    cameras = json.loads(json_out.read_text())["cameras"]
    table = pd.read_parquet(cameras_path(parquet_out))
    assert [c["trigger_pairing"] for c in cameras] == [case] * 3
    assert list(table["camera"]) == [c["camera"] for c in cameras]
    assert list(table["trigger_pairing"]) == [c["trigger_pairing"] for c in cameras]
    assert str(pq.read_schema(cameras_path(parquet_out)).field("trigger_pairing").type) in (
        "string",
        "large_string",
    )
