"""A camera topic's rows are packed into typed columns as they stream in: the tables, the
damaged-message warnings and the audit are the same whether rows are packed every row or
all at the end."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from syncaudit.audit.run import audit_log
from syncaudit.camera import rowstore
from syncaudit.camera.extract import CameraTableBuilder, image_row
from syncaudit.camera.rowstore import DamagedRow
from syncaudit.columns.table import Table
from syncaudit.errors import LogReadError
from syncaudit.logs import RawMessage
from syncaudit.rig import CameraConfig

REPO = Path(__file__).resolve().parents[2]
SAMPLE = REPO / "sample_logs" / "vlp16_three_cameras.mcap"


def _image(stamp_s: int, frame: str) -> RawMessage:
    """A ROS 1 sensor_msgs/Image head: seq, stamp, frame_id."""
    data = (
        (7).to_bytes(4, "little")
        + stamp_s.to_bytes(4, "little")
        + (0).to_bytes(4, "little")
        + len(frame).to_bytes(4, "little")
        + frame.encode()
    )
    return RawMessage("/img", "sensor_msgs/msg/Image", stamp_s * 10**9 + 5, data, "ros1")


def _equal_tables(a: Table, b: Table) -> None:
    assert a.columns.keys() == b.columns.keys() and len(a) == len(b)
    for name in a.columns:
        x, y = a[name], b[name]
        assert x.dtype == y.dtype, name
        assert x.tolist() == y.tolist(), name


def test_packed_parts_make_the_table_one_pack_makes(monkeypatch: pytest.MonkeyPatch) -> None:
    rows = []
    for i in range(11):
        rows.append(image_row(_image(100 + i, f"cam{i % 2}")))
        if i % 4 == 1:
            rows.append(DamagedRow("/img", i, f"cut {i}"))
    whole = CameraTableBuilder(CameraConfig(name="c")).images
    whole.extend(rows)
    monkeypatch.setattr(rowstore, "PACK_ROWS", 3)
    parts = CameraTableBuilder(CameraConfig(name="c")).images
    parts.extend(rows)
    assert len(parts._tables) == 3 and len(parts._pending) == 2  # packed as they came
    assert (len(parts), parts.readable) == (len(rows), 11)
    assert [d.reason for d in parts.damaged] == ["cut 1", "cut 5", "cut 9"]
    _equal_tables(parts.table(), whole.table())
    assert parts.table()["header_stamp_ns"].tolist() == [(100 + i) * 10**9 for i in range(11)]
    frames = parts.table()["frame_id"]
    assert frames[0] is frames[2]  # equal names share one object within a pack


def test_an_empty_store_is_an_empty_table_with_the_columns() -> None:
    store = CameraTableBuilder(CameraConfig(name="c")).triggers
    table = store.table()
    assert len(table) == 0 and "applied_delay_ns" in table
    assert table["log_time_ns"].dtype == np.int64


def test_a_store_of_damaged_rows_only_is_refused_by_the_builder() -> None:
    builder = CameraTableBuilder(CameraConfig(name="c", image_topic="/img"))
    builder.images.append(DamagedRow("/img", 1, "0 bytes"))
    with pytest.raises(LogReadError, match="all 1 messages on /img are damaged"):
        builder.build()


def test_the_audit_is_the_same_packed_every_row(monkeypatch: pytest.MonkeyPatch) -> None:
    expected = audit_log(SAMPLE, jobs=1).to_dict()
    monkeypatch.setattr(rowstore, "PACK_ROWS", 1)
    assert audit_log(SAMPLE, jobs=1).to_dict() == expected
