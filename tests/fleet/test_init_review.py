"""Issue 23 finding 5: `gate --init` says what it learnt and refuses logs that are not good.

From the sample logs (which `audit` calls FAIL) it wrote `error_mean_us max 2514.9`; from
LiDAR-only logs every camera check was off; logs disagreeing on the clock dropped that
check; all it printed was "policy from N log(s) written".
"""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from syncaudit.cli import app
from syncaudit.fleet.init_review import init_problems
from syncaudit.fleet.inputs import LogJob
from syncaudit.fleet.job import JobOptions, LogOutcome, run_log_job
from syncaudit.fleet.policy import load_policy
from syncaudit.simulate.sync_log import simulate_sync_log, sync_sim_config

from .conftest import THREE_CAMERAS

REAL = Path("/work/shared/data/lidar")
REAL_VLP16 = REAL / "velodyne_vlp16" / "1673400471837873222"


def _outcome(path: Path, rig: Path | None = None) -> LogOutcome:
    outcome = run_log_job(
        LogJob(str(path), rig_path=None if rig is None else str(rig)), JobOptions()
    )
    assert outcome.ok, outcome.error
    return outcome


@pytest.fixture(scope="module")
def good_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A correctly configured Pandar40P rig without tunnel: Eq. 5 about 130 us, below 250."""
    path = tmp_path_factory.mktemp("good") / "good.mcap"
    simulate_sync_log(path, sync_sim_config(lidar="Pandar40P", tunnel=False, seed=5, duration_s=3))
    return path


def test_sample_logs_are_refused_with_what_fails(tmp_path: Path) -> None:
    out = tmp_path / "p.yaml"
    result = CliRunner().invoke(app, ["gate", "--init", str(THREE_CAMERAS), "-o", str(out)])
    assert result.exit_code == 10 and not out.exists()
    assert "vlp16_three_cameras.mcap: fails the default thresholds" in result.output
    assert "front: error_mean_us = 1605.04 us (limit <= 250 us)" in result.output
    assert "no policy written" in result.output and "--accept-bad" in result.output


def test_accepted_anyway_it_says_each_limit_and_where_it_came_from(tmp_path: Path) -> None:
    out = tmp_path / "p.yaml"
    result = CliRunner().invoke(
        app, ["gate", "--init", str(THREE_CAMERAS), "-o", str(out), "--accept-bad"]
    )
    assert result.exit_code == 0, result.output
    assert "WARNING: vlp16_three_cameras.mcap: fails the default thresholds" in result.output
    assert (
        "learnt defaults.camera.error_mean_us: max 2514.9 us (1.5 x 1643.27 us + 50; worst: "
        "rear_left in vlp16_three_cameras.mcap) fail"
    ) in result.output
    assert "learnt defaults.log.required_topics: the 14 topic(s)" in result.output
    text = out.read_text()
    assert "# WARNING: written although the known-good logs are not good" in text
    assert "#   - vlp16_three_cameras.mcap: fails the default thresholds" in text
    load_policy(out)  # still a valid policy


def test_a_good_log_gives_a_policy_without_doubts(good_log: Path, tmp_path: Path) -> None:
    assert init_problems([_outcome(good_log)]) == []
    out = tmp_path / "p.yaml"
    result = CliRunner().invoke(app, ["gate", "--init", str(good_log), "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "WARNING" not in result.output and "WARNING" not in out.read_text()
    assert "learnt defaults.lidar.clock_synchronised: expect true" in result.output


@pytest.mark.skipif(not REAL_VLP16.is_dir(), reason="real recordings not mounted")
def test_lidar_only_logs_and_clock_disagreement_are_doubts(good_log: Path) -> None:
    lidar_only = _outcome(REAL_VLP16)
    (line,) = init_problems([lidar_only])
    assert line.startswith("1673400471837873222: no camera (a LiDAR-only log?)")
    problems = init_problems([_outcome(good_log), lidar_only])
    assert problems[-1] == (
        "the logs disagree on the LiDAR clock: synchronised in good.mcap, not in "
        "1673400471837873222; the clock check would be learnt as off"
    )


def test_a_cut_known_good_log_is_a_doubt(tmp_path: Path) -> None:
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(THREE_CAMERAS.read_bytes()[:600_000])
    outcome = _outcome(cut, Path(f"{THREE_CAMERAS}.rig.yaml"))
    (line,) = [p for p in init_problems([outcome]) if "truncated" in p]
    assert line.startswith("cut.mcap: fails the default thresholds: ")
    assert "truncated = true: cut off at byte 597772" in line
