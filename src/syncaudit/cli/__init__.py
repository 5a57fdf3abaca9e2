"""The `syncaudit` command line: thin commands over the library API.

One module per command (group); `common` holds the app, the run wrapper (errors -> one
line + exit code), consoles, the OutputSet helper and the options several commands share.

Adding a command: write `cli/<name>_command.py` with `@app.command()` (or a sub-app added with
`app.add_typer`), import the library inside the command's body (`syncaudit --help` must
stay fast), run the body through `run(job)`, route every file it writes through
`output_set(...)` (checked before any work, committed together), print through `emit`,
and import the module below.
"""

from __future__ import annotations

from syncaudit.cli import (
    audit_command,
    calib_command,
    fleet_commands,
    info_command,
    rig_command,
    simulate_command,
)
from syncaudit.cli.common import app, main

__all__ = [
    "app",
    "audit_command",
    "calib_command",
    "fleet_commands",
    "info_command",
    "main",
    "rig_command",
    "simulate_command",
]
