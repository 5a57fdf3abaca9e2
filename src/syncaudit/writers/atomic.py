"""One-file atomic writes for library code: an `OutputSet` of one target, replacing it.

Commands route their outputs through `syncaudit.writers.outputs.OutputSet` directly (all
targets checked first, committed together); these helpers are for library code that
writes a single file on its own. Same rules: a temporary beside the target, renamed at the
end, never a partial file; an existing target is replaced only when it carries the tool's
mark (`writers.provenance`: the caller writes the mark into the text), anything else is
refused; a device (`/dev/null`) is written through.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import IO

from syncaudit.writers.outputs import OutputSet


def write_atomic(path: Path, fill: Callable[[IO[str]], None]) -> None:
    """Create `path` (or replace the tool's own) with what `fill` writes, never partially.

    Raises:
        OutputError: naming `path`, when it cannot be written.
    """
    with OutputSet(overwrite=True) as outputs, outputs.open_text(path) as handle:
        fill(handle)


def write_text_atomic(path: Path, text: str) -> None:
    """Atomically create a text file, or replace one the tool wrote (it carries the mark)."""
    with OutputSet(overwrite=True) as outputs:
        outputs.write_text(path, text)
