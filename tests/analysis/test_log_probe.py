"""One probe of an open log serves the rig guess, the rig check, the camera placement and the
read plan: each first look at the log (LiDAR topics, camera topics, /tf_static, a Nebula
scan, Ouster metadata) is read once however many steps ask."""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

import pytest

from syncaudit.audit import probe as probe_module
from syncaudit.audit.plan import read_plan
from syncaudit.audit.probe import LogProbe
from syncaudit.audit.rig_check import check_rig_against_log
from syncaudit.audit.rig_guess import guess_rig, render_starter_rig
from syncaudit.logs import open_log

SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"


def _counted(monkeypatch: pytest.MonkeyPatch, calls: Counter[str], name: str) -> None:
    real = getattr(probe_module, name)

    def counting(*args: Any, **kwargs: Any) -> Any:
        calls[name] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(probe_module, name, counting)


@pytest.mark.parametrize("log_name", ["vlp16_three_cameras.mcap", "pandar40p_adaptive.mcap"])
def test_every_step_shares_one_look_at_the_log(
    log_name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls: Counter[str] = Counter()
    for name in ("guess_lidar_topics", "probe_camera_topics", "tf_static_yaws"):
        _counted(monkeypatch, calls, name)
    with open_log(SAMPLES / log_name) as log:
        probe = LogProbe(log)
        rig, _ = guess_rig(probe)
        starter = render_starter_rig(probe)  # guesses again and places the cameras
        checked, _ = check_rig_against_log(probe, rig)
        plan, _ = read_plan(probe, checked, list(checked.cameras))
        again = render_starter_rig(log)  # a log without a probe: a fresh look
    assert starter == again
    assert plan.lidar_topic == rig.lidar.topic
    assert calls["guess_lidar_topics"] == 2  # the shared probe's one, and the fresh one's
    assert calls["probe_camera_topics"] == 2
    assert calls["tf_static_yaws"] == 2  # the guessed cameras are placed by /tf_static
