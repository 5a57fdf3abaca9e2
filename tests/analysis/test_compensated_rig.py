"""A correctly configured rig passes the gate in the tunnel too (issue 23).

With constant delays the error follows the exposure (2 -> 12 -> 2 ms in the tunnel), so a
rig whose constant delay is right still fails there (Eq. 5 ~1.6 ms). The simulator's
`--delays compensated` triggers each frame with its own exposure compensated exactly (what
a rig with exposure feed-forward applies): such a rig of every simulated LiDAR model passes
`audit --gate` in the tunnel, at its floor, and the same rig 300 us late fails.
"""

from __future__ import annotations

import json
import typing
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from syncaudit.cli import app
from syncaudit.simulate import LidarModel
from syncaudit.simulate.delays import CompensatedDelays

runner = CliRunner()
MODELS = typing.get_args(LidarModel)


def _simulate(out: Path, *args: str) -> dict[str, typing.Any]:
    run = runner.invoke(
        app, ["simulate", "sync", str(out), "--duration", "6", "--tunnel", "--seed", "5", *args]
    )
    assert run.exit_code == 0, run.output
    truth: dict[str, typing.Any] = json.loads(Path(f"{out}.truth.json").read_text())
    return truth


def _gate(out: Path) -> tuple[int, dict[str, typing.Any]]:
    json_out = out.with_name(out.name + ".json")
    run = runner.invoke(
        app,
        ["audit", str(out), "--gate", "--json-out", str(json_out)],  # the rig beside it
    )
    return run.exit_code, json.loads(json_out.read_text())


@pytest.mark.parametrize("model", MODELS)
def test_a_compensated_rig_passes_in_the_tunnel_and_300_us_late_fails(
    tmp_path: Path, model: str
) -> None:
    truth = _simulate(tmp_path / "good.mcap", "--lidar", model, "--delays", "compensated")
    for cam in truth["cameras"].values():
        assert cam["applied_delay"]["mode"] == "compensated"
        assert cam["applied_delay"]["max_ns"] - cam["applied_delay"]["min_ns"] > 4_000_000
    code, audit = _gate(tmp_path / "good.mcap")
    assert code == 0, [(c["camera"], c["error_mean_us"], c["floor"]) for c in audit["cameras"]]
    for cam in audit["cameras"]:
        assert cam["verdict"] == "pass"
        assert cam["error_mean_us"] == pytest.approx(
            truth["cameras"][cam["camera"]]["error_mean_ns"] / 1e3, abs=5.0
        )
        # At its floor: what is left is the packet quantisation and the chain jitter.
        floor = cam["floor"]["error_mean_us"]
        assert cam["error_mean_us"] - floor < max(10.0, 0.05 * floor)
    _simulate(
        tmp_path / "late.mcap", "--lidar", model, "--delays", "compensated",
        "--delay-error-us", "300",
    )  # fmt: skip
    code, audit = _gate(tmp_path / "late.mcap")
    assert code == 10
    assert all(c["verdict"] == "fail" for c in audit["cameras"])


def test_constant_delays_of_the_same_rig_fail_in_the_tunnel(tmp_path: Path) -> None:
    """The case the compensated source exists for: Eq. 5 ~1.6 ms with a right constant."""
    truth = _simulate(tmp_path / "constant.mcap", "--delays", "constant")
    code, audit = _gate(tmp_path / "constant.mcap")
    assert code == 10
    for cam in audit["cameras"]:
        assert cam["error_mean_us"] > 1_000.0
        assert truth["cameras"][cam["camera"]]["applied_delay"]["mode"] == "constant"


def test_compensated_delays_take_each_frames_half_exposure_off() -> None:
    exposure = np.array([2_000_000, 12_000_000, 4_000_000], dtype=np.int64)
    applied = CompensatedDelays().applied_ns(10_000_000, exposure)
    # mean half exposure 3 ms: 10 + 3 - 1, 10 + 3 - 6, 10 + 3 - 2 ms
    assert applied.tolist() == [12_000_000, 7_000_000, 11_000_000]
    assert int(applied.mean()) == 10_000_000
    assert CompensatedDelays().applied_ns(1_000_000, exposure).min() == 0  # never negative


def test_delays_option_is_checked_and_controller_still_works(tmp_path: Path) -> None:
    bad = runner.invoke(app, ["simulate", "sync", str(tmp_path / "x.mcap"), "--delays", "ideal"])
    assert bad.exit_code == 64
    assert "--delays: 'ideal' is not one of constant, controller, compensated" in bad.output
    clash = runner.invoke(
        app,
        ["simulate", "sync", str(tmp_path / "x.mcap"), "--delays", "compensated", "--controller"],
    )
    assert clash.exit_code == 64 and "give one" in clash.output
    for args in (["--controller"], ["--delays", "controller"]):
        out = tmp_path / f"c{len(args)}.mcap"
        truth = _simulate(out, *args)
        assert {c["applied_delay"]["mode"] for c in truth["cameras"].values()} == {"controller"}


def test_the_floor_does_not_charge_a_rig_for_its_per_frame_delays() -> None:
    """The same frames, compensated or not: one floor (was 1455.6 us against 285.5 us)."""
    from syncaudit.analysis.floor import error_floor

    rng = np.random.default_rng(1)
    exposure = np.repeat([2e6, 12e6, 2e6], 30)
    residual = rng.normal(0.0, 300e3, exposure.size)  # quantisation and jitter
    phase, chain = rng.uniform(0, 1.3e6, exposure.size), rng.normal(500e3, 40e3, exposure.size)
    constant = error_floor(residual + exposure / 2, exposure, phase, chain, np.full(90, 15e6))
    applied = 15e6 + exposure.mean() / 2 - exposure / 2
    compensated = error_floor(residual + exposure.mean() / 2, exposure, phase, chain, applied)
    assert compensated.error_mean_ns == pytest.approx(constant.error_mean_ns, rel=1e-9)
    assert constant.error_mean_ns < 300e3
    assert error_floor(residual + exposure / 2, exposure, phase, chain).error_mean_ns == (
        pytest.approx(constant.error_mean_ns, rel=1e-9)
    )
