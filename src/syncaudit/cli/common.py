"""What every command shares: the app, the run wrapper, consoles, outputs and common options.

Kept free of heavy imports (no numpy, pandas, pydantic, rich, the simulator): `syncaudit
--help` imports only this and typer. A command imports what it needs inside its body.
"""

from __future__ import annotations

import contextlib
import copy
import difflib
import functools
import importlib
import json
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Annotated, Any, NoReturn, TypeVar

import typer
from typer.core import TyperArgument, TyperGroup
from typer.main import get_command_name
from typer.models import CommandInfo

try:  # typer >= 0.22 vendors click
    from typer._click import exceptions as click_errors
    from typer._click import utils as click_utils
except ImportError:  # pragma: no cover - older typer on the click package
    from click import exceptions as click_errors  # type: ignore[no-redef,import-not-found,unused-ignore]
    from click import utils as click_utils  # type: ignore[no-redef,import-not-found,unused-ignore]


from syncaudit import __version__
from syncaudit.cli.startup import pause_gc, resume_gc
from syncaudit.errors import (
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_USAGE,
    ConfigError,
    Interrupted,
    MissingExtraError,
    OutputError,
    SyncauditError,
    UsageError,
)

if TYPE_CHECKING:
    from rich.console import Console

    from syncaudit.writers.outputs import OutputSet

T = TypeVar("T")

PIPE_WIDTH = 100_000
"""Console width when output is not a terminal: tables full width, lines never wrapped."""

_MAIN_PID = os.getpid()


def _on_sigterm(signum: int, frame: FrameType | None) -> None:
    """SIGTERM in the main process unwinds like Ctrl-C (outputs are rolled back)."""
    if os.getpid() != _MAIN_PID:  # a forked worker that inherited the handler: just die
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)
        return
    raise Interrupted(f"signal {signum}")


@contextlib.contextmanager
def signals_raise() -> Iterator[None]:
    """While running a command, SIGTERM raises `Interrupted` (SIGINT already raises).

    The previous handler comes back afterwards (the app may run inside a test or a host
    program).
    """
    global _MAIN_PID
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _MAIN_PID = os.getpid()
    previous = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


HELP_OPTIONS = ["-h", "--help"]
"""Help on every command and group (click contexts pass them on to their children)."""


def _usage_line(exc: click_errors.UsageError) -> str:
    """A click usage error as one line naming the option, with where to find help."""
    if isinstance(exc, click_errors.NoSuchOption):
        message = f"No such option: {exc.option_name}"
        nearest = nearest_option(exc.option_name, exc.ctx)
        if nearest is not None:
            message += f" (did you mean {nearest}?)"
    else:
        message = " ".join(exc.format_message().split())
    where = exc.ctx.command_path if exc.ctx is not None else "syncaudit"
    return f"error: {message} (see '{where} --help')"


def nearest_option(typed: str, ctx: Any) -> str | None:
    """The command's option nearest to an unknown one (`--overwite` -> `--overwrite`), if any.

    Names are compared without their dashes, so that `--` alone makes nothing close (click
    offers `--jobs` for `--bogus`).
    """
    if ctx is None:
        return None
    names = [
        name
        for param in ctx.command.get_params(ctx)
        for name in (*param.opts, *param.secondary_opts)
        if name.startswith("-")
    ]
    by_word = {name.lstrip("-"): name for name in names}
    close = difflib.get_close_matches(typed.lstrip("-"), list(by_word), n=1, cutoff=0.6)
    return by_word[close[0]] if close else None


def first_sentence(text: str) -> str:
    """A help text's first sentence, whole: up to a full stop before a capital or the end.

    click cuts at the first full stop (`Eq. 5` became `Eq.`) and past 45 characters.
    """
    flat = " ".join(text.split("\n\n", 1)[0].split())
    for index, char in enumerate(flat):
        rest = flat[index + 1 :]
        if char == "." and (not rest or (rest.startswith(" ") and rest[1:2].isupper())):
            return flat[: index + 1]
    return flat


class _UsageArgument(TyperArgument):
    """An argument the usage line names as users type it: `LOG`, `LOG...`, `[OUT]`.

    typer writes a required argument as `{log}`.
    """

    def _usage_display_name(self) -> str:
        name = self.metavar or (self.name or "arg").upper()
        if self.nargs != 1:
            name += "..."
        return name if self.required else f"[{name}]"


def _polish(command: Any) -> None:
    """The help of every command of the tree as users read it.

    A command without a `short_help` gets its first sentence uncut; arguments are named
    in capitals on the usage line (`_UsageArgument`).
    """
    for param in getattr(command, "params", []):
        if type(param) is TyperArgument:
            if param.metavar is None:
                param.metavar = (param.name or "arg").upper()
            param.__class__ = _UsageArgument
    for child in getattr(command, "commands", {}).values():
        if not child.short_help and child.help:
            child.short_help = first_sentence(child.help)
        _polish(child)


_NO_ARGS_IS_HELP: type[click_errors.UsageError] = getattr(
    click_errors, "NoArgsIsHelpError", click_errors.UsageError
)


class SyncauditGroup(TyperGroup):
    """The app's click group: usage errors exit 64 with one line, interrupts exit 130."""

    def main(  # type: ignore[override]
        self,
        args: Sequence[str] | None = None,
        prog_name: str | None = None,
        complete_var: str | None = None,
        standalone_mode: bool = True,
        **extra: Any,
    ) -> Any:
        """Run the command line; in standalone mode exit with the documented code."""
        _polish(self)
        try:
            with signals_raise():
                code = super().main(
                    args=args,
                    prog_name=prog_name,
                    complete_var=complete_var,
                    standalone_mode=False,
                    **extra,
                )
        except _NO_ARGS_IS_HELP as exc:
            if exc.ctx is not None:
                help_text = exc.ctx.get_help()
                emit(lambda: typer.echo(help_text))
            code = EXIT_USAGE
        except click_errors.UsageError as exc:
            say(_usage_line(exc))
            code = EXIT_USAGE
        except (typer.Abort, KeyboardInterrupt, Interrupted):
            say("error: interrupted")
            code = EXIT_INTERRUPTED
        except click_errors.ClickException as exc:
            say(f"error: {' '.join(exc.format_message().split())}")
            code = EXIT_USAGE
        except OSError as exc:  # click's own printing (help, version) on a full disk
            say(f"error: stdout: {exc.strerror or exc} (the help was not written)")
            code = OutputError.exit_code
        except SystemExit as exc:
            # click exits 1 when its own printing (a help text) meets a closed pipe, after
            # wrapping the streams; the command bodies print through `emit` and `say`.
            if exc.code != 1 or not isinstance(sys.stdout, click_utils.PacifyFlushWrapper):
                raise
            reader_gone()
            code = 0
        if not standalone_mode:
            return code
        sys.exit(code if isinstance(code, int) else 0)


app = typer.Typer(
    name="syncaudit",
    cls=SyncauditGroup,
    help="Audit LiDAR-camera synchronisation and LiDAR extrinsics in MCAP, ROS 2 and ROS 1 logs.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    context_settings={"help_option_names": HELP_OPTIONS},
)


def _show_version(value: bool) -> None:
    if value:
        typer.echo(f"syncaudit {__version__}")
        raise typer.Exit(0)


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_show_version, is_eager=True, help="Print the version and exit."
        ),
    ] = False,
) -> None:
    """Audit LiDAR-camera synchronisation and LiDAR extrinsics in MCAP, ROS 2 and ROS 1 logs."""


# -- options shared by several commands ----------------------------------------------------

LogArgument = Annotated[
    str,
    typer.Argument(
        help="MCAP file, ROS 2 bag (dir/.db3/.mcap), ROS 1 .bag or .pcap/.pcapng capture; or "
        "its URL (s3://, gs://, az://, http(s)://)."
    ),
]
RigOption = Annotated[
    Path | None,
    typer.Option(
        "--rig", help="Rig file (YAML/TOML/JSON); topics and cameras are guessed without it."
    ),
]
LidarMetadataOption = Annotated[
    Path | None,
    typer.Option(
        "--lidar-metadata",
        help="Ouster sensor metadata JSON for a .pcap/.pcapng capture (default: the .json "
        "of the same name beside it).",
    ),
]
LidarCaptureOption = Annotated[
    Path | None,
    typer.Option(
        "--lidar-capture",
        help="A .pcap/.pcapng capture of the LiDAR recorded beside LOG on the same host: "
        "the LiDAR timing is taken from it (its clock is the log's host clock).",
    ),
]
JsonFlag = Annotated[
    bool, typer.Option("--json", help="Print the result as JSON instead of tables.")
]
JsonOutOption = Annotated[
    Path | None, typer.Option("--json-out", help="Also write the full JSON result here.")
]
HtmlOption = Annotated[
    Path | None, typer.Option("--html", help="Write a self-contained HTML report here.")
]
GateFlag = Annotated[bool, typer.Option("--gate", help="Exit 10 when the check fails (CI gate).")]
OverwriteFlag = Annotated[
    bool,
    typer.Option(
        "--overwrite",
        help="Replace outputs syncaudit wrote before (never another file; all or none).",
    ),
]


def log_location(text: str) -> str | Path:
    """A log argument as the readers take it: a URL kept as given (a Path would fold its
    '//' into '/'), anything else a path."""
    from syncaudit.remote.urls import is_url

    return text if is_url(text) else Path(text)


def local_paths(*items: str | Path | None) -> tuple[Path | None, ...]:
    """The local paths among `items` (URLs and None dropped to None): the inputs an
    output must not overwrite."""
    return tuple(item if isinstance(item, Path) else None for item in items)


# -- running a command ---------------------------------------------------------------------


_STDOUT_LOST: list[str] = []
"""Why the result could not be written on stdout (disk full, I/O error): `run` then exits 8,
unless the command already ended with its own code (a failed gate stays 10)."""


def say(line: str) -> None:
    """One line on stderr; a reader that went away (`2>&1 | head`) is not an error.

    The exit code is decided by the caller, never by the pipe nor by a full disk.
    """
    try:
        sys.stderr.write(line + "\n")
        sys.stderr.flush()
    except (BrokenPipeError, ValueError):  # ValueError: the stream is closed
        reader_gone()
    except OSError:  # stderr on a full disk: nowhere left to say anything
        _silence(sys.stderr)


def fail(message: str, code: int) -> NoReturn:
    """Print one `error:` line on stderr and exit with `code`."""
    say(f"error: {message}")
    raise typer.Exit(code)


def run(job: Callable[[], T], *, imports: Callable[[], object] | None = None) -> T:
    """Run a command body: known errors become one line on stderr and their exit code.

    The one mapping of the command line from errors to exit codes (`errors.EXIT_CODES`).
    `imports` (the modules the body needs whatever its options) run first, still within
    the console script's start-up pause of the garbage collector (`cli.startup`), which
    ends before `job`. A reader that went away is not an error: printing stops, the exit
    code stays the one the command reached (`emit`, `say`).
    """
    try:
        if imports is not None:
            imports()
        resume_gc()
        result = job()
        if _STDOUT_LOST:
            fail(f"stdout: {_STDOUT_LOST[0]} (the result was not written)", OutputError.exit_code)
        return result
    except typer.Exit:  # a job that already said why (`fail`) and chose its code
        raise
    except SyncauditError as exc:
        fail(" ".join(str(exc).split()), exc.exit_code)
    except (KeyboardInterrupt, Interrupted):
        fail("interrupted", EXIT_INTERRUPTED)
    except BrokenPipeError:  # printed without `emit`: nothing else is known to have failed
        reader_gone()
        raise typer.Exit(0) from None
    except OSError as exc:  # an output the OutputSet did not name (should not happen)
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        fail(f"{where}{exc.strerror or exc}", OutputError.exit_code)
    except Exception as exc:
        if os.environ.get("SYNCAUDIT_DEBUG"):
            raise
        fail(
            f"internal error: {type(exc).__name__}: {' '.join(str(exc).split())} "
            "(set SYNCAUDIT_DEBUG=1 for a traceback and please report it)",
            EXIT_INTERNAL,
        )


def require_extra(module: str, *, extra: str, option: str) -> None:
    """Refuse before any work when `option` needs an extra that is not installed (exit 64)."""
    try:
        importlib.import_module(module)
    except ImportError:
        raise MissingExtraError(
            f"{option} needs {module.split('.')[0]}: pip install 'syncaudit[{extra}]'"
        ) from None


def reader_gone() -> None:
    """Point stdout and stderr at /dev/null once a reader went away (`| head`, `2>&1 | head`).

    Both: with `2>&1` they are one pipe, and the next line on either would fail again.
    """
    for stream in (sys.stdout, sys.stderr):
        _silence(stream)


def _silence(stream: Any) -> None:
    """Point one stream's file descriptor at /dev/null (a reader gone, a full disk)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, stream.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):
        pass  # not a real file (a test runner's buffer): nothing to silence


def emit(show: Callable[[], None]) -> None:
    """Print a result on stdout; a reader that went away (`| head`) is not an error, a full
    disk is (exit 8 at the end of `run`, unless the command failed on its own)."""
    try:
        show()
        sys.stdout.flush()
    except BrokenPipeError:
        reader_gone()
    except OSError as exc:
        _STDOUT_LOST.append(exc.strerror or str(exc))
        _silence(sys.stdout)


def _console_class() -> type[Console]:
    """rich's Console, but a reader that went away raises BrokenPipeError (rich's exits 1)."""
    from rich.console import Console

    class _Console(Console):
        def on_broken_pipe(self) -> None:
            """Stop printing and let `emit` / `say` carry on (the exit code is not the pipe's)."""
            self.quiet = True
            raise BrokenPipeError

    return _Console


def stdout_console() -> Console:
    """A rich console on stdout: styled on a terminal; plain, unwrapped, full width otherwise."""
    console = _console_class()
    if sys.stdout.isatty():
        return console(highlight=False)
    return console(width=PIPE_WIDTH, soft_wrap=True, highlight=False, no_color=True)


@functools.cache
def stderr_console() -> Console:
    """The rich console on stderr (progress, warnings), made on first use."""
    return _console_class()(stderr=True, soft_wrap=True)


def note(markup: str) -> None:
    """One rich-markup line on stderr; a reader that went away is not an error."""
    try:
        stderr_console().print(markup, highlight=False)
    except BrokenPipeError:
        reader_gone()
    except OSError:  # stderr on a full disk
        _silence(sys.stderr)


def print_json(data: Any) -> None:
    """The result as indented JSON on stdout."""
    text = json.dumps(data, indent=2, allow_nan=False) + "\n"

    def show() -> None:
        sys.stdout.write(text)

    emit(show)


def json_text(data: Any) -> str:
    """The result as an indented JSON document (what `--json-out` writes), marked as ours."""
    from syncaudit.writers.provenance import marked_json

    return json.dumps(marked_json(data), indent=2, allow_nan=False) + "\n"


def output_set(
    *, overwrite: bool, inputs: Iterable[Path | None] = (), targets: Iterable[Path | None] = ()
) -> OutputSet:
    """An OutputSet with every (given) target checked now, before any work."""
    from syncaudit.writers.outputs import OutputSet

    outputs = OutputSet(overwrite=overwrite, inputs=inputs)
    try:
        for target in targets:
            if target is not None:
                outputs.claim(target)
    except BaseException:
        outputs.discard()
        raise
    return outputs


def only_command(argv: Sequence[str]) -> typer.Typer:
    """The app with only the command `argv` starts with, when it names one exactly.

    typer builds the click parameters of every command (type hints, defaults) before it
    parses the command line: ~5 ms for the commands that will not run. A first argument
    that names no command (an option, a typo, nothing) gets the whole app, for its help
    and its errors.
    """
    if not argv:
        return app
    commands = [c for c in app.registered_commands if _command_name(c) == argv[0]]
    groups = [g for g in app.registered_groups if g.name == argv[0]]
    if len(commands) + len(groups) != 1:
        return app
    only = copy.copy(app)
    only.registered_commands = commands
    only.registered_groups = groups
    return only


def _command_name(command: CommandInfo) -> str | None:
    """The name typer gives a registered command."""
    if command.name:
        return command.name
    return get_command_name(command.callback.__name__) if command.callback else None


def _open_closed_streams() -> None:
    """Give a closed stdin/stdout/stderr (`>&-`) /dev/null, as a reader that went away.

    Else the first file the command opens takes descriptor 1 or 2, and a line meant for the
    terminal would be written into an output file.
    """
    for fd, name in ((0, "stdin"), (1, "stdout"), (2, "stderr")):
        try:
            os.fstat(fd)
            continue
        except OSError:
            pass
        opened = os.open(os.devnull, os.O_RDWR)
        if opened != fd:  # pragma: no cover - lower descriptors are open by now
            os.dup2(opened, fd)
            os.close(opened)
        if getattr(sys, name) is None:
            setattr(sys, name, open(fd, "r" if fd == 0 else "w", closefd=False))  # noqa: SIM115


def main() -> None:
    """Console-script entry point.

    Exits without the interpreter's teardown (~60 ms with numpy and pandas loaded): by
    then every output file is committed and closed, and the streams are flushed here.
    The garbage collector is paused until the command's imports are done (`cli.startup`).
    """
    pause_gc()
    _open_closed_streams()
    try:
        only_command(sys.argv[1:])()
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        if exc.code is not None and not isinstance(exc.code, int):
            print(exc.code, file=sys.stderr)
    # A reader that went away (e.g. `| head`) is not an error.
    with contextlib.suppress(OSError):
        sys.stdout.flush()
    with contextlib.suppress(OSError):
        sys.stderr.flush()
    os._exit(code)


def option_error(exc: ConfigError, options: Mapping[str, str]) -> UsageError:
    """A config refused by its model, worded with the option that set the bad key.

    `options` maps config fields to the options setting them (`stamp_semantics` ->
    `--stamp`). A key no option sets keeps its path as the config names it; the path is
    never rewritten piecewise (that made `cameras.0.--stamp`).
    """
    for key in reversed(exc.key_path):
        if isinstance(key, str) and key in options:
            return UsageError(f"{options[key]}: {exc.detail or exc}")
    detail = str(exc).split(": ", 1)[-1] if str(exc).startswith("invalid ") else str(exc)
    return UsageError(detail.removeprefix("(top level): "))
