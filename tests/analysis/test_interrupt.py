"""Signals during the worker phase (issue 10 item 15), with real processes: Ctrl-C to the
whole process group and SIGTERM to the main process both end `syncaudit audit` with exit
130, no traceback, and no worker left alive, in bounded time."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from slowed_cli import start, survivors, wait_for_workers
from syncaudit.simulate.rig_file import rig_from_truth
from syncaudit.simulate.sync_log import SyncSimConfig, simulate_sync_log

SLEEP_S = 1.0
"""Each task is held this long in its worker, so that the worker phase lasts seconds on
any machine (the signal must arrive while it runs)."""


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("sig")
    out = folder / "log.mcap"
    truth = simulate_sync_log(out, SyncSimConfig(seed=5, duration_s=20.0, lidar_model="VLP-32C"))
    rig = folder / "rig.yaml"
    data = rig_from_truth(truth).model_dump(mode="json", exclude_defaults=True)  # type: ignore[arg-type]
    rig.write_text(yaml.safe_dump(data, sort_keys=False))
    return out, rig


def _interrupt(log: tuple[Path, Path], send: str) -> tuple[int, str, list[int], float]:
    out, rig = log
    # Two workers whatever the machine's cores (the default is one per core).
    proc = start(["audit", str(out), "--rig", str(rig), "--jobs", "2"], sleep_s=SLEEP_S)
    workers = wait_for_workers(proc, 2, poll_s=0.005)
    if proc.poll() is not None or len(workers) < 2:
        os.killpg(proc.pid, signal.SIGKILL)
        _, stderr = proc.communicate()
        pytest.fail(f"the audit's two workers never ran (exit {proc.returncode}): {stderr}")
    time.sleep(0.05)
    began = time.monotonic()
    if send == "SIGINT-group":
        os.killpg(proc.pid, signal.SIGINT)
    else:
        os.kill(proc.pid, signal.SIGTERM)
    try:
        _, stderr = proc.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail(f"{send}: the audit hung after the signal")
    took = time.monotonic() - began
    return proc.returncode, stderr, survivors(workers), took


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="uses /proc")
@pytest.mark.parametrize("send", ["SIGINT-group", "SIGTERM-main", "SIGINT-group", "SIGINT-group"])
def test_interrupted_audit_exits_130_and_leaves_no_worker(
    log: tuple[Path, Path], send: str
) -> None:
    code, stderr, survivors, took = _interrupt(log, send)
    assert code == 130, stderr
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, stderr
    assert survivors == []
    assert took < 10
