"""The results database's lock: runs take turns, and no lock file is ever left behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from syncaudit.errors import OutputError
from syncaudit.fleet.database import ResultsDB


def test_a_second_writer_waits_and_nothing_is_left(tmp_path: Path) -> None:
    db = ResultsDB(tmp_path / "fleet.duckdb")
    with db.connect() as con:
        con.execute("SELECT 1")
        with (
            pytest.raises(OutputError, match="still locked by another run"),
            ResultsDB(tmp_path / "fleet.duckdb", lock_timeout_s=0.2).connect(),
        ):
            pass
    with ResultsDB(tmp_path / "fleet.duckdb", lock_timeout_s=0.2).connect(read_only=True):
        pass  # free again once the first is done
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fleet.duckdb"]


def test_a_killed_holder_leaves_no_lock(tmp_path: Path) -> None:
    code = (
        "import sys, time\n"
        "from syncaudit.fleet.database import ResultsDB\n"
        "with ResultsDB(sys.argv[1]).connect():\n"
        "    print('locked', flush=True)\n"
        "    time.sleep(60)\n"
    )
    holder = subprocess.Popen(
        [sys.executable, "-c", code, str(tmp_path / "fleet.duckdb")],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "locked"
        os.kill(holder.pid, signal.SIGKILL)
        holder.wait(timeout=30)
    finally:
        if holder.poll() is None:
            holder.kill()
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".lock")]
    start = time.monotonic()  # the kernel dropped the lock with the process: no wait
    with ResultsDB(tmp_path / "fleet.duckdb", lock_timeout_s=5).connect():
        pass
    assert time.monotonic() - start < 5
    # DuckDB's journal of the killed run is replayed by the next writer, then gone.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fleet.duckdb"]
