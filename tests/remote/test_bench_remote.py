"""benchmarks/bench_remote.py --quick (what CI runs of it): it runs, the audits agree, bytes are tight."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def test_bench_remote_short_mode() -> None:
    result = subprocess.run(
        [
            sys.executable,
            str(REPO / "benchmarks" / "bench_remote.py"),
            "--quick",
            "--repeat",
            "1",
            "--json",
            "--transfer",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout)
    assert figures["chunks_fetched"] == figures["chunks_total"] == 7
    # Everything fetched is a needed chunk, the header or the summary section.
    assert figures["fetched_bytes"] <= figures["size_bytes"]
    assert figures["fetched_over_needed"] <= 1.05
    assert figures["server"] == "threaded" and figures["time_ratio"] > 0
    # The transfer alone moved the whole file both ways; the floors are ratios.
    transfer = figures["transfer"]
    assert transfer["bytes"] == figures["size_bytes"]
    assert set(transfer["http"]) == set(transfer["pread"]) >= {"client_sys_s", "server_sys_s"}
    assert 0 < figures["floor_server_elsewhere"] <= figures["floor_local_parallelism"]
