"""Every header-stamp convention a rig can declare gives the true Eq. 4/5 errors.

Frames here take their exposure from flir ImageMetaData (whole microseconds, no start of
its own), so the exposure start comes from the header stamp and the rig's `stamp`:
exposure start, middle or end, or the trigger reaching the camera (checkpoint 246), which
the exposure follows by t4 (taken from the frame's trigger record, else the rig's
`analysis.assumed_t4_us`). t4 is made large here (400 us) so that ignoring it shows.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from syncaudit.audit.run import AuditResult, audit_log
from syncaudit.rig import Rig
from syncaudit.simulate.rig_file import rig_from_truth
from syncaudit.simulate.sync_log import CameraSim, LatencyDist, SyncSimConfig, simulate_sync_log

CAMERAS = [
    CameraSim(name="start", yaw_deg=0.0, stamp_semantics="exposure_start", delay_error_us=600.0),
    CameraSim(name="middle", yaw_deg=90.0, stamp_semantics="exposure_middle", delay_error_us=700.0),
    CameraSim(name="end", yaw_deg=180.0, stamp_semantics="exposure_end", delay_error_us=800.0),
    CameraSim(name="trigger", yaw_deg=270.0, stamp_semantics="trigger", delay_error_us=900.0),
]
T4 = LatencyDist(mean_us=400.0, std_us=30.0, min_us=300.0)
ERROR_NS = 5_000
"""ImageMetaData rounds t5 to the microsecond; the packets' azimuths give ~2.5 us."""


def _simulate(tmp_path: Path, **config: Any) -> tuple[Path, dict[str, Any]]:
    out = tmp_path / "log.mcap"
    settings = {
        "cameras": CAMERAS,
        "duration_s": 3.0,
        "seed": 23,
        "t4": T4,
        "exposure_messages": ("flir_meta",),
        **config,
    }
    return out, simulate_sync_log(out, SyncSimConfig(**settings))


def _check(result: AuditResult, truth: dict[str, Any], *, names: tuple[str, ...]) -> None:
    by_name = {c.sync.camera: c.sync for c in result.cameras}
    for name in names:
        sync, t = by_name[name], truth["cameras"][name]
        assert sync.frames_paired == len(t["frames"]), name
        assert sync.error_mean_ns == pytest.approx(t["error_mean_ns"], abs=ERROR_NS), name
        assert sync.error_signed_mean_ns == pytest.approx(
            t["error_signed_mean_ns"], abs=ERROR_NS
        ), name


def test_each_declared_stamp_gives_the_true_errors(tmp_path: Path) -> None:
    out, truth = _simulate(tmp_path)
    result = audit_log(out, rig_from_truth(truth), jobs=1)
    _check(result, truth, names=tuple(c.name for c in CAMERAS))
    trigger = next(c.sync for c in result.cameras if c.sync.camera == "trigger")
    assert not any("t4" in w for w in trigger.warnings)


def test_trigger_stamps_without_trigger_records_use_the_assumed_t4(tmp_path: Path) -> None:
    out, truth = _simulate(tmp_path, trigger_messages=False)
    rig = rig_from_truth(truth)
    t4_us = truth["cameras"]["trigger"]["t4_mean_ns"] / 1e3
    assumed = Rig.model_validate(
        {**rig.model_dump(), "analysis": {**rig.analysis.model_dump(), "assumed_t4_us": t4_us}}
    )
    _check(audit_log(out, assumed, jobs=1), truth, names=("trigger",))
    # Without t4 the start stays at the trigger: t_l early by t4, and the camera says so.
    bare = audit_log(out, rig, jobs=1)
    sync = next(c.sync for c in bare.cameras if c.sync.camera == "trigger")
    signed = truth["cameras"]["trigger"]["error_signed_mean_ns"]
    assert sync.error_signed_mean_ns == pytest.approx(signed - t4_us * 1e3, abs=ERROR_NS)
    assert any("stamped at the trigger (246) without t4" in w for w in sync.warnings)
