"""The garbage collector paused while a command starts up (its imports build ~100k objects).

A command's start-up is imports: typer, pydantic, numpy, the readers and decoders build
modules, classes and functions that live as long as the process. CPython's collector,
triggered every 700 new objects, traverses them again and again (the full collections
the whole heap): about a tenth of the CPU time of a sample-sized audit, for nothing, since
nothing made by an import is garbage. So the console script (`common.main`) pauses it
before the command line is parsed, and the command resumes it once its imports are done
(`run(job, imports=...)`, or when its body starts): what the imports built is frozen (no
collection looks at it again, and forked workers never copy its pages by collecting it),
and collection goes on as before for the command's own work.

Commands that read logs in worker processes (one per core) also start numpy's OpenBLAS with
one thread (`one_blas_thread`): its default pool of a thread per core costs ~30 ms of CPU
at numpy's import, and their numpy work is elementwise (no BLAS) or would oversubscribe
the cores the workers use.

The pause is a raised threshold, not `gc.disable()`: a command that forgot to resume still
collects, just rarely. Library code and tests that call the app directly never pause.
"""

from __future__ import annotations

import gc
import os
import sys

PAUSED_THRESHOLD = 200_000
"""New objects between two young collections while paused (CPython's default is 700):
more than a command's imports make, few enough to bound a forgotten pause."""

_saved: tuple[int, ...] | None = None
"""The collector's thresholds before the pause; None when not paused."""


def pause_gc() -> None:
    """Pause collection for a command's start-up (the console script only)."""
    global _saved
    if _saved is None:
        _saved = gc.get_threshold()
        gc.set_threshold(PAUSED_THRESHOLD, *_saved[1:])


def resume_gc() -> None:
    """End the start-up pause: freeze what exists (imports) and collect as before.

    Nothing happens when the collector was not paused (the app called from a test).
    """
    global _saved
    if _saved is None:
        return
    gc.freeze()
    gc.set_threshold(*_saved)
    _saved = None


def gc_paused() -> bool:
    """Whether the start-up pause is on (for tests)."""
    return _saved is not None


def one_blas_thread() -> None:
    """Have OpenBLAS (numpy's BLAS) start one thread, unless the environment sets a number.

    OpenBLAS reads it when numpy loads it: with numpy already imported (the app run inside
    a test or a host program) nothing is changed. Inherited by the workers.
    """
    if "numpy" not in sys.modules:
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
