"""Advice a user can act on (issue 23): replayed recommendations, the floor, the gate.

Every log is simulated with known truth: a correctly configured rig (constant ideal delay,
steady light) must pass the default gate at its floor for every LiDAR model; the same rig
300 us late must fail with a constant shift of about -300 us; the tunnel must ask for
per-frame compensation, not for a constant. The recommendation's expected Eq. 5/6 are
recomputed from `audit --csv` (error moves one-for-one with the delay).
"""

from __future__ import annotations

import io
import json
import typing
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from syncaudit.cli import app
from syncaudit.simulate import LidarModel

runner = CliRunner()
MODELS = typing.get_args(LidarModel)


def _simulate(tmp_path: Path, name: str, *args: str) -> Path:
    out = tmp_path / name
    run = runner.invoke(app, ["simulate", "sync", str(out), "--duration", "6", *args])
    assert run.exit_code == 0, run.output
    return out


def _gate(out: Path, tmp_path: Path) -> tuple[int, dict[str, typing.Any], str]:
    """Exit code, JSON and CSV of `audit --gate` with the simulated rig."""
    json_out, csv_out = tmp_path / f"{out.name}.json", tmp_path / f"{out.name}.csv"
    run = runner.invoke(
        app,
        [
            "audit",
            str(out),
            "--rig",
            f"{out}.rig.yaml",
            "--gate",
            "--json-out",
            str(json_out),
            "--csv",
            str(csv_out),
        ],
    )
    return run.exit_code, json.loads(json_out.read_text()), csv_out.read_text()


@pytest.mark.parametrize("model", MODELS)
def test_a_correct_rig_passes_at_its_floor_and_300_us_late_fails(
    tmp_path: Path, model: str
) -> None:
    good = _simulate(tmp_path, "good.mcap", "--lidar", model, "--no-tunnel", "--seed", "5")
    code, audit, _ = _gate(good, tmp_path)
    assert code == 0, [c["recommendation"] for c in audit["cameras"]]
    for cam in audit["cameras"]:
        rec = cam["recommendation"]
        assert rec["action"] == "none", rec
        assert rec["shift_us"] is None
        # At its floor: within the margin (10 us or 5 %) of what the design reaches.
        assert rec["current_error_mean_us"] - rec["floor_us"] < max(10.0, 0.05 * rec["floor_us"])
        assert cam["verdict"] == "pass"
    late = _simulate(
        tmp_path, "late.mcap", "--lidar", model, "--no-tunnel", "--seed", "5",
        "--delay-error-us", "300",
    )  # fmt: skip
    code, audit, _ = _gate(late, tmp_path)
    assert code == 10
    for cam in audit["cameras"]:
        rec = cam["recommendation"]
        assert rec["action"] == "shift_trigger", rec
        # The truth is -300 us; the median of the quantised errors is within a packet's
        # quantisation of it (VLP-16: 1.3 ms packets).
        assert rec["shift_us"] == pytest.approx(-300.0, abs=60.0)
        assert rec["expected_error_mean_us"] < rec["current_error_mean_us"] - 50.0
        assert cam["verdict"] == "fail"


def _eq5_eq6(errors: np.ndarray) -> tuple[float, float]:
    """Eq. 5 / Eq. 6 written out again (not the package's functions)."""
    a = np.abs(errors)
    n = a.size
    return float(a.mean()), float((np.mean(a * a) - a.mean() ** 2) * n / (n - 1))


@pytest.mark.parametrize("tunnel", ["--tunnel", "--no-tunnel"])
def test_expected_error_is_eq5_of_the_csv_with_the_action_applied(
    tmp_path: Path, tunnel: str
) -> None:
    out = _simulate(tmp_path, "log.mcap", tunnel, "--seed", "3", "--delay-error-us", "400")
    _, audit, csv = _gate(out, tmp_path)
    frames = pd.read_csv(io.StringIO(csv))
    for cam in audit["cameras"]:
        rows = frames[(frames["camera"] == cam["camera"]) & frames["paired"]]
        moved = rows["error_signed_ns"] + (rows["advised_delay_ns"] - rows["applied_delay_ns"])
        mean_ns, var_ns2 = _eq5_eq6(moved.to_numpy())
        rec = cam["recommendation"]
        assert rec["expected_error_mean_us"] == pytest.approx(mean_ns / 1e3, rel=1e-9)
        assert rec["expected_error_var_us2"] == pytest.approx(var_ns2 / 1e6, rel=1e-9)
        recorded_ns, _ = _eq5_eq6(rows["error_signed_ns"].to_numpy())
        assert rec["current_error_mean_us"] == pytest.approx(recorded_ns / 1e3, rel=1e-9)
        if rec["action"] == "shift_trigger":
            shifts = (rows["advised_delay_ns"] - rows["applied_delay_ns"]) / 1e3
            assert np.allclose(shifts, rec["shift_us"], atol=1e-6)


def test_a_tunnel_asks_for_per_frame_compensation_that_beats_the_seed(tmp_path: Path) -> None:
    out = _simulate(tmp_path, "tunnel.mcap", "--seed", "5")
    _, audit, _ = _gate(out, tmp_path)
    for cam in audit["cameras"]:
        rec = cam["recommendation"]
        assert rec["action"] == "per_frame_compensation", rec
        assert rec["shift_us"] is None
        assert "exposure" in rec["why"]
        policies = {w["policy"]: w for w in cam["what_if"]}
        recorded = policies["as recorded"]["error_mean_us"]
        shift = policies["constant shift"]["error_mean_us"]
        seed = policies["seed controller (Eq. 2, running average)"]["error_mean_us"]
        ours = policies["feed-forward + dead band (ours)"]["error_mean_us"]
        # The exposure swings 2 -> 12 ms: t_l moves by 5 ms, no constant follows it.
        assert recorded > 1000.0 and shift > 0.8 * recorded
        assert ours < 0.5 * seed
        assert rec["expected_error_mean_us"] == ours
        assert cam["controller"] is not None
