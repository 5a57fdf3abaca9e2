"""All-or-nothing outputs: every target checked first, written aside, committed together.

One rule for every output of every command (`--json-out`, `--csv`, `--html`,
`--pairings`, `simulate`'s log, truth and rig, `calib`'s outputs):

1. Every target is checked before any work (`OutputSet.add`): an existing target is
   replaced only when it carries this tool's mark (`syncaudit.writers.provenance`) and
   `overwrite` is given; anything else (a recording, a foreign folder or file, a symbolic
   link) is refused whatever the flags (exit 8). An input of the run, or one path given
   as two outputs, is a usage error (exit 64), also through a symbolic link.
2. Everything is written to temporaries in a hidden folder beside each target (same file
   system, so the final step is a rename).
3. `commit()` moves every temporary onto its target with SIGINT/SIGTERM blocked; if a
   rename fails, the targets already replaced get their previous content back.
4. A failure or an interruption before the commit (`discard()`, or leaving the `with`
   block by an exception) removes every temporary; the previous files stay as they were.

A target that exists and is neither a file nor a folder (`/dev/null`, a FIFO, a
terminal) is written through at commit time instead of being replaced.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import sqlite3
import stat
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from types import TracebackType
from typing import IO, Literal

from syncaudit.errors import OutputError, UsageError
from syncaudit.writers.provenance import SIDECAR_SUFFIXES, refusal, sidecar_of, sidecar_text

OutputKind = Literal["file", "dir"]

_TMP_PREFIX = ".syncaudit-"
_TMP_SUFFIX = ".tmp"


def _is_device(path: Path) -> bool:
    """A target that exists and is neither a regular file nor a folder (/dev/null, a FIFO)."""
    try:
        mode = path.stat().st_mode
    except OSError:
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def _reason(exc: BaseException) -> str:
    if isinstance(exc, OSError):
        return exc.strerror or str(exc)
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


class OutputSet:
    """The outputs of one run, committed together or not at all (see the module doc).

    Use as a context manager: leaving the block normally commits, an exception (including
    KeyboardInterrupt) discards. `add` every target before starting the work.
    """

    def __init__(
        self,
        *,
        overwrite: bool = False,
        inputs: Iterable[str | Path | None] = (),
        overwrite_hint: str = "pass --overwrite to replace it",
    ) -> None:
        self.overwrite = overwrite
        self._hint = overwrite_hint
        self._inputs = {Path(p).resolve() for p in inputs if p is not None}
        self._targets: dict[Path, tuple[Path, OutputKind]] = {}
        """target as given -> (its temporary, kind), in the order added."""
        self._resolved: set[Path] = set()
        """The targets resolved: a second name for one file is found without rescanning
        (a gate run adds one report per log: thousands of targets)."""
        self._tmp_dirs: dict[Path, Path] = {}
        """folder of targets -> the hidden temporary folder made in it."""
        self._claimed: set[Path] = set()
        """The targets the user named (resolved): a second option naming one is refused."""
        self._done = False

    # -- planning -------------------------------------------------------------------------

    def add(self, target: str | Path, *, kind: OutputKind = "file") -> Path:
        """Check `target` now and return the temporary path to write it to.

        Raises OutputError when the target exists without `overwrite`, is a folder the tool
        did not write, is an input of the run, is given twice, or its folder is missing.
        """
        target = Path(target)
        if self._done:
            raise RuntimeError("outputs already committed or discarded")
        if target in self._targets:
            tmp, known = self._targets[target]
            if known != kind:
                raise UsageError(
                    f"{target}: given as two different outputs (one path, two outputs)"
                )
            return tmp
        resolved = target.resolve()
        if resolved in self._inputs:
            raise UsageError(f"{target}: is an input of this run; refusing to write over it")
        if resolved in self._resolved:
            raise UsageError(f"{target}: given as two different outputs (one path, two outputs)")
        if target.is_symlink() or target.exists():
            self._check_existing(target, kind)
        parent = target.parent
        if not parent.is_dir():
            raise OutputError(f"{target}: cannot write (folder {parent} does not exist)")
        tmp = self._tmp_dir(parent) / target.name
        self._targets[target] = (tmp, kind)
        self._resolved.add(resolved)
        return tmp

    def refuse_input(self, target: str | Path) -> None:
        """Raise UsageError (exit 64) when `target` names an input of the run (any name)."""
        if Path(target).resolve() in self._inputs:
            raise UsageError(f"{target}: is an input of this run; refusing to write over it")

    def claim(self, target: str | Path, *, kind: OutputKind = "file") -> Path:
        """`add` a target a user named on the command line: naming one path twice is refused.

        `add` of a target already added returns its temporary (a log writer adds the path
        its command claimed); `claim` is what the options go through.

        Raises:
            UsageError: the path (or another name of it) is claimed already (exit 64).
        """
        resolved = Path(target).resolve()
        if resolved in self._claimed and not _is_device(Path(target)):
            raise UsageError(f"{target}: given as two different outputs (one path, two outputs)")
        tmp = self.add(target, kind=kind)
        self._claimed.add(resolved)
        return tmp

    def _check_existing(self, target: Path, kind: OutputKind) -> None:
        if _is_device(target):
            return  # written through at commit, never replaced
        why = refusal(target)
        if why is not None:
            raise OutputError(f"{target}: {why}; not replacing it (choose another name)")
        if not self.overwrite:
            raise OutputError(f"{target}: exists ({self._hint})")

    def _tmp_dir(self, parent: Path) -> Path:
        key = parent.resolve()
        if key not in self._tmp_dirs:
            try:
                made = tempfile.mkdtemp(prefix=_TMP_PREFIX, suffix=_TMP_SUFFIX, dir=parent)
            except OSError as exc:
                raise OutputError(f"{parent}: cannot write outputs here ({_reason(exc)})") from None
            self._tmp_dirs[key] = Path(made)
        return self._tmp_dirs[key]

    def temporary(self, target: str | Path) -> Path:
        """The temporary path of a target already `add`ed."""
        return self._targets[Path(target)][0]

    @property
    def targets(self) -> list[Path]:
        """The targets, in the order they were added."""
        return list(self._targets)

    # -- writing --------------------------------------------------------------------------

    @contextlib.contextmanager
    def writing(self, target: str | Path) -> Iterator[Path]:
        """Yield the temporary of `target`; turn a write failure into an OutputError naming it.

        Catches what a full disk or a lost permission raises on the way: OSError and
        sqlite3's OperationalError (ROS 2 bags).
        """
        tmp = self.temporary(target) if Path(target) in self._targets else self.add(target)
        try:
            yield tmp
        except (OSError, sqlite3.Error) as exc:
            raise OutputError(f"{target}: cannot write ({_reason(exc)})") from None

    def write_text(self, target: str | Path, text: str) -> None:
        """Write a text output (UTF-8, newlines as given) into its temporary."""
        with self.writing(target) as tmp, tmp.open("w", encoding="utf-8", newline="") as handle:
            handle.write(text)

    def write_bytes(self, target: str | Path, data: bytes) -> None:
        """Write a binary output into its temporary."""
        with self.writing(target) as tmp:
            tmp.write_bytes(data)

    @contextlib.contextmanager
    def open_text(self, target: str | Path) -> Iterator[IO[str]]:
        """Open the temporary of a text output for writing (UTF-8, newlines as given)."""
        with self.writing(target) as tmp, tmp.open("w", encoding="utf-8", newline="") as handle:
            yield handle

    # -- ending ---------------------------------------------------------------------------

    def commit(self) -> None:
        """Move every written temporary onto its target, all or none; then clean up.

        Raises OutputError naming the target when a rename fails (the targets replaced
        before it are restored) or when a target was never written.
        """
        if self._done:
            return
        blocked = {signal.SIGINT, signal.SIGTERM}
        old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, blocked)
        try:
            self._commit()
        finally:
            self.discard()
            signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)

    def _commit(self) -> None:
        for target, (tmp, _) in self._targets.items():
            if not (tmp.exists() or tmp.is_symlink()):
                raise OutputError(f"{target}: was not written (nothing committed)")
            appeared = (target.exists() or target.is_symlink()) and not _is_device(target)
            if appeared and not self.overwrite:
                raise OutputError(f"{target}: appeared while writing; not replacing it")
        replaced: list[tuple[Path, Path | None]] = []  # (target, where its old content went)
        moves = self._with_sidecars()
        try:
            for target, tmp in moves:
                if _is_device(target):
                    with tmp.open("rb") as src, target.open("wb") as dst:
                        shutil.copyfileobj(src, dst)
                    continue
                backup: Path | None = None
                if target.exists() or target.is_symlink():
                    backup = tmp.with_name(f"{tmp.name}.previous")
                    os.rename(target, backup)
                replaced.append((target, backup))
                os.rename(tmp, target)
        except OSError as exc:
            failed = target
            for done, backup in reversed(replaced):
                with contextlib.suppress(OSError):
                    if done.is_dir() and not done.is_symlink():
                        shutil.rmtree(done)
                    elif done.exists() or done.is_symlink():
                        done.unlink()
                    if backup is not None:
                        os.rename(backup, done)
            raise OutputError(
                f"{failed}: cannot write ({_reason(exc)}); no output was changed"
            ) from None

    def _with_sidecars(self) -> list[tuple[Path, Path]]:
        """(target, temporary) of every output, plus the sidecar marking each CSV written."""
        moves: list[tuple[Path, Path]] = []
        for target, (tmp, kind) in self._targets.items():
            moves.append((target, tmp))
            if kind == "file" and target.suffix.lower() in SIDECAR_SUFFIXES:
                if _is_device(target) or not tmp.is_file():
                    continue
                mark = tmp.with_name(f"{tmp.name}.syncaudit-mark")
                try:
                    mark.write_text(sidecar_text(tmp.read_bytes()), encoding="utf-8")
                except OSError as exc:
                    raise OutputError(f"{target}: cannot write ({_reason(exc)})") from None
                moves.append((sidecar_of(target), mark))
        return moves

    def discard(self) -> None:
        """Remove every temporary (and replaced previous outputs); targets stay as they are."""
        self._done = True
        for tmp_dir in self._tmp_dirs.values():
            shutil.rmtree(tmp_dir, ignore_errors=True)
        self._tmp_dirs.clear()

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.discard()

    def __del__(self) -> None:
        # An OutputSet dropped without commit() must not leave temporaries behind.
        if not getattr(self, "_done", True):
            self.discard()
