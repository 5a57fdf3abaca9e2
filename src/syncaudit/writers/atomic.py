"""Write output files atomically: a temp file beside the target, then `os.replace`."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import IO

from syncaudit.errors import OutputError


def write_atomic(path: Path, fill: Callable[[IO[str]], None]) -> None:
    """Create `path` with what `fill` writes, never leaving a partial file behind."""
    path = Path(path)
    if path.exists() and not path.is_file():
        # A device or FIFO (/dev/null, /dev/stdout, a pipe): write through, never replace it.
        try:
            with path.open("w", encoding="utf-8", newline="") as handle:
                fill(handle)
        except OSError as exc:
            raise OutputError(f"{path}: cannot write ({exc.strerror or exc})") from exc
        return
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent or ".")
    except OSError as exc:
        raise OutputError(f"{path}: cannot write ({exc.strerror or exc})") from exc
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as handle:
            fill(handle)
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; outputs follow the umask
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_text_atomic(path: Path, text: str) -> None:
    """Atomically write a text file."""

    def fill(handle: IO[str]) -> None:
        handle.write(text)

    write_atomic(path, fill)
