"""The command line reads as one tool: help everywhere and whole, usage as users type it,
the nearest real option suggested, exit codes that survive a closed pipe."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import typer
from typer.testing import CliRunner

from syncaudit.cli import app
from syncaudit.cli.common import first_sentence, option_error
from syncaudit.errors import ConfigError

SAMPLES = Path(__file__).resolve().parents[2] / "sample_logs"
runner = CliRunner()


def _paths() -> Iterator[list[str]]:
    """Every command and group of the app, as the words that name it."""
    stack: list[tuple[list[str], Any]] = [([], typer.main.get_command(app))]
    while stack:
        words, command = stack.pop()
        yield words
        for name, child in getattr(command, "commands", {}).items():
            stack.append(([*words, name], child))


COMMANDS = sorted(_paths())


def test_the_walk_sees_every_command() -> None:
    assert ["gate"] in COMMANDS and ["fleet", "report"] in COMMANDS
    assert ["simulate", "calib"] in COMMANDS and len(COMMANDS) >= 11


@pytest.mark.parametrize("words", COMMANDS, ids=" ".join)
def test_dash_h_is_help_everywhere(words: list[str]) -> None:
    short = runner.invoke(app, [*words, "-h"])
    long = runner.invoke(app, [*words, "--help"])
    assert short.exit_code == 0, short.output
    assert short.stdout == long.stdout and short.stdout.startswith("Usage:")


@pytest.mark.parametrize("words", COMMANDS, ids=" ".join)
def test_usage_lines_name_arguments_as_typed(words: list[str]) -> None:
    usage = runner.invoke(app, [*words, "--help"]).stdout.splitlines()[0]
    assert "{" not in usage and "}" not in usage, usage
    arguments = usage.split("[OPTIONS]", 1)[1].split()
    assert all(word.strip("[].") == word.strip("[].").upper() for word in arguments), usage


def test_the_log_arguments_are_log() -> None:
    usage = {" ".join(w): runner.invoke(app, [*w, "-h"]).stdout.splitlines()[0] for w in COMMANDS}
    for name in ("audit", "info", "rig", "calib"):
        assert usage[name].endswith(f"{name} [OPTIONS] LOG")
    assert usage["gate"].endswith("gate [OPTIONS] LOG...")


@pytest.mark.parametrize("words", [w for w in COMMANDS if w in ([], ["fleet"], ["simulate"])])
def test_command_lists_are_never_cut(words: list[str]) -> None:
    text = runner.invoke(app, [*words, "--help"]).stdout
    listing = text.split("Commands:", 1)[1]
    assert "..." not in listing and "…" not in listing
    group = typer.main.get_command(app)
    for word in words:
        group = group.commands[word]  # type: ignore[attr-defined]
    flat = " ".join(listing.split())
    for name, command in group.commands.items():  # type: ignore[attr-defined]
        whole = command.short_help or first_sentence(command.help or "")
        assert f"{name} {whole}" in flat


def test_fleet_report_help_is_whole() -> None:
    """click cut it to "Dashboard of Eq." (its full stop ends the first sentence)."""
    listing = runner.invoke(app, ["fleet", "--help"]).stdout
    assert "Dashboard and tables of the results database." in listing
    long = "Dashboard of Eq. 5 error, delays and t1..t4 per vehicle. More here."
    assert first_sentence(long) == "Dashboard of Eq. 5 error, delays and t1..t4 per vehicle."


@pytest.mark.parametrize(
    ("args", "suggested"),
    [
        (["audit", "x.mcap", "--bogus"], None),
        (["audit", "x.mcap", "--overwite"], "--overwrite"),
        (["audit", "x.mcap", "--jsn"], "--json"),
        (["gate", "x.mcap", "--polcy", "p.yaml"], "--policy"),
        (["calib", "x.mcap", "--topic", "a,b"], "--topics"),
    ],
)
def test_an_unknown_option_suggests_the_nearest_real_one(
    args: list[str], suggested: str | None
) -> None:
    result = runner.invoke(app, args)
    assert result.exit_code == 64
    line = result.stderr.strip()
    assert line.startswith(f"error: No such option: {args[2]}") and "\n" not in line
    if suggested is None:
        assert "did you mean" not in line and "--jobs" not in line
    else:
        assert f"(did you mean {suggested}?)" in line


def _closed_pipe(*args: str) -> int:
    """Exit code of the command with stdout and stderr on a pipe nobody reads any more."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "syncaudit", *args],
            stdout=write_end,
            stderr=write_end,
            check=False,
            timeout=120,
        )
    finally:
        os.close(write_end)
    return proc.returncode


def test_exit_codes_survive_a_closed_pipe(tmp_path: Path) -> None:
    """`audit LOG --gate 2>&1 | head -1` exited 1 once the pipe closed, not 10."""
    failing = SAMPLES / "vlp16_short.bag"  # guessed rig: the gate fails
    gated = ["audit", str(failing), "--no-rig", "--gate"]
    assert runner.invoke(app, [*gated, "--json"]).exit_code == 10
    assert _closed_pipe(*gated) == 10
    assert _closed_pipe("audit", str(tmp_path / "none.mcap")) == 2
    assert _closed_pipe("audit", "x.mcap", "--bogus") == 64
    assert _closed_pipe("gate", "--no-db", str(tmp_path / "none.mcap")) == 64
    assert _closed_pipe("--help") == 0


def test_config_errors_name_the_option_that_set_the_key() -> None:
    """A simulator setting refused: named by its option, not `cameras.0.--stamp`."""
    from syncaudit.simulate.sync_log import sync_sim_config

    with pytest.raises(ConfigError) as caught:
        sync_sim_config(stamp="bogus")  # type: ignore[arg-type]
    assert caught.value.key_path == ("cameras", 0, "stamp_semantics")
    message = str(option_error(caught.value, {"stamp_semantics": "--stamp"}))
    assert message.startswith("--stamp: Input should be 'exposure_start'")
    assert "cameras" not in message
    unnamed = str(option_error(caught.value, {}))
    assert unnamed.startswith("cameras.0.stamp_semantics: Input should be")
