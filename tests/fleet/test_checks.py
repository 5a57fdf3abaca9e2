"""Every policy check fires just past its limit and not just inside it, on a real audit."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest

from syncaudit.fleet.checks import _camera_values, drop_rate, evaluate, verdict
from syncaudit.fleet.job import LogOutcome
from syncaudit.fleet.policy import CameraChecks, parse_policy

OFF_CAMERA = {name: None for name in CameraChecks.model_fields}
OFF = {
    "camera": OFF_CAMERA,
    "lidar": {"clock_synchronised": None},
    "log": {"truncated": None, "damaged_messages": None, "missing_index": None},
}


def _policy(group: str, check: str, spec: dict[str, Any]) -> Any:
    defaults: dict[str, Any] = {k: dict(v) for k, v in OFF.items()}
    defaults.setdefault(group, {})[check] = spec
    return parse_policy({"defaults": defaults}, "test")


def _judged(outcome: LogOutcome, group: str, check: str, spec: dict[str, Any]) -> list[Any]:
    results = evaluate(outcome, _policy(group, check, spec), None)
    assert results and all(r.check == check for r in results)
    return results


@pytest.mark.parametrize("check", list(CameraChecks.model_fields))
def test_camera_checks_fire_past_the_limit_only(
    three_cameras_outcome: LogOutcome, check: str
) -> None:
    cams = three_cameras_outcome.audit["cameras"]  # type: ignore[index]
    values = {c["camera"]: _camera_values(c)[check] for c in cams}
    assert all(v is not None for v in values.values()), values
    bound = "min" if check == "paired_fraction" else "max"
    if bound == "max":
        worst = max(v for v in values.values() if v is not None)
        inside, past = worst * 1.001 + 1e-9, worst * 0.999
    else:
        worst = min(v for v in values.values() if v is not None)
        inside, past = worst * 0.999, worst * 1.001 + 1e-9
    ok = _judged(three_cameras_outcome, "camera", check, {bound: inside})
    assert len(ok) == 3 and all(r.passed for r in ok)
    bad = _judged(three_cameras_outcome, "camera", check, {bound: past, "severity": "warn"})
    failing = {r.subject for r in bad if not r.passed}
    beyond = {
        name
        for name, v in values.items()
        if v is not None and (v > past if bound == "max" else v < past)
    }
    assert failing == beyond and any(values[s] == worst for s in failing)
    assert all(r.severity == "warn" for r in bad)
    for result in bad:
        value = values[result.subject]
        assert value is not None and f"{value:.6g}" in result.message
        assert f"limit {bound and ('<=' if bound == 'max' else '>=')} {past:.6g}" in result.message


def test_lidar_checks(three_cameras_outcome: LogOutcome) -> None:
    lidar = three_cameras_outcome.audit["lidar"]  # type: ignore[index]
    rate = drop_rate(lidar)
    assert rate == pytest.approx(6 / (7465 + 6))
    for check, value in (
        ("rpm", lidar["rpm"]),
        ("packets_per_revolution", lidar["packets_per_revolution"]),
        ("drop_rate", rate),
    ):
        (ok,) = _judged(
            three_cameras_outcome, "lidar", check, {"min": value * 0.99, "max": value * 1.01}
        )
        assert ok.passed and ok.value == pytest.approx(value)
        (low,) = _judged(three_cameras_outcome, "lidar", check, {"max": value * 0.99})
        (high,) = _judged(three_cameras_outcome, "lidar", check, {"min": value * 1.01})
        assert not low.passed and not high.passed
    assert lidar["clock_synchronised"] is True
    (ok,) = _judged(three_cameras_outcome, "lidar", "clock_synchronised", {"expect": True})
    (bad,) = _judged(three_cameras_outcome, "lidar", "clock_synchronised", {"expect": False})
    assert ok.passed and not bad.passed


def test_log_checks(three_cameras_outcome: LogOutcome) -> None:
    duration = three_cameras_outcome.audit["duration_s"]  # type: ignore[index]
    (ok,) = _judged(three_cameras_outcome, "log", "duration_s", {"min": duration - 0.01})
    (bad,) = _judged(three_cameras_outcome, "log", "duration_s", {"min": duration + 0.01})
    assert ok.passed and not bad.passed
    (ok,) = _judged(
        three_cameras_outcome,
        "log",
        "required_topics",
        {"topics": ["/velodyne_packets", "/tf_static"]},
    )
    (bad,) = _judged(
        three_cameras_outcome,
        "log",
        "required_topics",
        {"topics": ["/velodyne_packets", "/gps/fix"]},
    )
    assert ok.passed and ok.value == 0
    assert not bad.passed and bad.value == 1 and bad.message == "missing: /gps/fix"


def test_calibration_checks(three_cameras_outcome: LogOutcome) -> None:
    spec = {"max": 0.25}
    # The sample log has no point clouds: the check has nothing to judge and is silent.
    assert evaluate(three_cameras_outcome, _policy("calibration", "rotation_deg", spec), None) == []
    calibrated = dataclasses.replace(
        three_cameras_outcome,
        calibration=[
            {
                "topic": "/left/points",
                "rotation_diff_deg": 0.1,
                "translation_diff_cm": 3.0,
                "reason": None,
            },
            {
                "topic": "/right/points",
                "rotation_diff_deg": 0.4,
                "translation_diff_cm": 1.0,
                "reason": None,
            },
        ],
    )
    rot = _judged(calibrated, "calibration", "rotation_deg", spec)
    assert [(r.subject, r.passed) for r in rot] == [
        ("/left/points", True),
        ("/right/points", False),
    ]
    trans = _judged(calibrated, "calibration", "translation_cm", {"max": 2.0})
    assert [(r.subject, r.passed) for r in trans] == [
        ("/left/points", False),
        ("/right/points", True),
    ]
    failed = dataclasses.replace(
        three_cameras_outcome, calibration_error="/left/points has 1 stop(s)"
    )
    (missing,) = _judged(failed, "calibration", "rotation_deg", spec)
    assert not missing.passed and missing.value is None and "1 stop" in missing.message


def test_verdicts(three_cameras_outcome: LogOutcome) -> None:
    warn = evaluate(
        three_cameras_outcome,
        _policy("camera", "error_mean_us", {"max": 1, "severity": "warn"}),
        None,
    )
    fail = evaluate(three_cameras_outcome, _policy("camera", "error_mean_us", {"max": 1}), None)
    ok = evaluate(three_cameras_outcome, _policy("camera", "error_mean_us", {"max": 1e6}), None)
    assert verdict(three_cameras_outcome, warn) == "warn"
    assert verdict(three_cameras_outcome, fail) == "fail"
    assert verdict(three_cameras_outcome, ok) == "pass"
    no_cameras = dataclasses.replace(
        three_cameras_outcome, audit={**three_cameras_outcome.audit, "cameras": []}
    )  # type: ignore[dict-item]
    assert verdict(no_cameras, []) == "fail"
    assert verdict(dataclasses.replace(three_cameras_outcome, audit=None, error="x"), []) == "error"
