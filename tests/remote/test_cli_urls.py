"""`syncaudit audit|info|rig URL` read the URLs the gate takes (http(s)://, s3://) by ranges,
and print what they print for the local file (the log named by its URL instead)."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from syncaudit.cli import app

from .conftest import SAMPLES, ServerState

runner = CliRunner()
LOGS = ("vlp16_three_cameras.mcap", "vlp16_short.bag")
# --no-rig: the rig beside the log is tested on its own below.
COMMANDS = (["audit", "--json", "--no-rig"], ["info", "--json"], ["rig"])


def _output(args: list[str]) -> str:
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    return result.stdout


def _same_as_local(command: list[str], url: str, local: Path) -> None:
    """The command's output on `url` is its output on `local`, the URL in place of the path."""
    expected = _output([command[0], str(local), *command[1:]])
    got = _output([command[0], url, *command[1:]])
    assert str(local) in expected
    assert got == expected.replace(str(local), url)


@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: c[0])
@pytest.mark.parametrize("name", LOGS)
def test_cli_on_an_http_url_prints_what_it_prints_for_the_file(
    http_root: tuple[str, ServerState], command: list[str], name: str
) -> None:
    base, state = http_root
    (state.root / name).symlink_to(SAMPLES / name)
    _same_as_local(command, f"{base}/{name}", SAMPLES / name)
    assert state.ranged_bytes > 0 and state.served_bytes == state.ranged_bytes  # by ranges only


@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: c[0])
def test_cli_on_an_s3_url_prints_what_it_prints_for_the_file(
    s3_endpoint: str, command: list[str]
) -> None:
    _same_as_local(command, "s3://fleet/uploads/car1/a.mcap", SAMPLES / LOGS[0])
    _same_as_local(command, "s3://fleet/uploads/car2/b.bag", SAMPLES / LOGS[1])


def test_cli_on_a_missing_url_is_one_line_and_exit_2(http_root: tuple[str, ServerState]) -> None:
    base, _ = http_root
    result = runner.invoke(app, ["audit", f"{base}/none.mcap?sig=secret"])
    assert result.exit_code == 2
    assert f"{base}/none.mcap" in result.output and "sig=secret" not in result.output
    assert "Traceback" not in result.output


def test_cli_on_a_bag_that_cannot_be_read_by_ranges_says_why_in_one_line(
    http_root: tuple[str, ServerState],
) -> None:
    base, state = http_root
    (state.root / "bag").symlink_to(SAMPLES / "vlp16_short_ros2")  # SQLite storage
    result = runner.invoke(app, ["info", f"{base}/bag", "--json"])
    assert result.exit_code == 2
    assert "not read by ranges: SQLite storage" in result.output
    assert len(result.output.strip().splitlines()) == 1 and "Traceback" not in result.output


def test_audit_of_a_url_takes_the_rig_beside_it_as_for_the_file(
    http_root: tuple[str, ServerState],
) -> None:
    """`LOG.rig.yaml` beside a remote log is asked for (one request) and used, said on
    stderr, the query string kept (a container's token covers the rig too)."""
    base, state = http_root
    name = LOGS[0]
    for file in (name, f"{name}.rig.yaml"):
        (state.root / file).symlink_to(SAMPLES / file)
    local = runner.invoke(app, ["audit", str(SAMPLES / name), "--json"])
    remote = runner.invoke(app, ["audit", f"{base}/{name}?sig=t0ken", "--json"])
    assert remote.exit_code == local.exit_code, remote.output
    assert remote.stdout == local.stdout.replace(str(SAMPLES / name), f"{base}/{name}")
    assert f"using rig {name}.rig.yaml beside the log" in remote.stderr
    assert f"/{name}.rig.yaml?sig=t0ken bytes=0-" in " ".join(state.requests)


def test_audit_of_a_url_with_no_rig_beside_guesses_and_a_refused_one_is_said(
    http_root: tuple[str, ServerState],
) -> None:
    base, state = http_root
    name = LOGS[0]
    (state.root / name).symlink_to(SAMPLES / name)
    guessed = _output(["audit", f"{base}/{name}", "--json"])
    assert guessed == _output(["audit", f"{base}/{name}", "--json", "--no-rig"])
    state.redirects[f"/{name}.rig.yaml"] = (403, "")  # a URL signed for the log alone
    refused = runner.invoke(app, ["audit", f"{base}/{name}", "--json"])
    assert refused.exit_code == 0 and refused.stdout == guessed
    assert "cannot read the rig beside the log" in refused.stderr
    assert "HTTP 403" in refused.stderr and "--rig to give one" in refused.stderr


def test_a_bad_rig_beside_a_url_is_exit_6_naming_it(http_root: tuple[str, ServerState]) -> None:
    base, state = http_root
    name = LOGS[0]
    (state.root / name).symlink_to(SAMPLES / name)
    (state.root / f"{name}.rig.yaml").write_text("lidar: {topic: 3, rpm: fast}\n")
    result = runner.invoke(app, ["audit", f"{base}/{name}?sig=secret"])
    assert result.exit_code == 6, result.output
    assert f"{base}/{name}.rig.yaml" in result.output and "sig=secret" not in result.output
    assert len(result.output.strip().splitlines()) == 1 and "Traceback" not in result.output
