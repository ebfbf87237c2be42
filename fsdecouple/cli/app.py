"""The ``fsdecouple`` Typer app: consoles, shared options, errors and the entry point.

Each command (in the modules beside this one) parses its arguments, calls one
library function, renders the result and picks the exit code: 0 done, 1 a gate
failed (``--max-gamma``), 2 bad input (one line on stderr, no traceback, no
output file).  Nothing outside this package imports typer.
"""

from __future__ import annotations

import contextlib
import gc
import json
import math
import os
import re
import signal
import sys
import warnings
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
)
from rich.segment import Segment
from rich.table import Table
from rich.text import Text
from typer.core import TyperGroup

from .. import __version__
from ..errors import FsdecoupleError, InputError, printable
from ..files.outputs import names_a_directory
from ..reporting.narrow import REDIRECTED, fit_width, needed_width

# Each command imports what only it needs (pandas, libsvm, scipy, matplotlib),
# so that `apply` and `show` start in a fraction of a second.

# Output that is not a terminal (a CI log read with grep) is never cut or wrapped: a
# six-axis cv table is 30 gamma columns wide, and a sentence stays on its line.
# Tables take their natural width; nothing here is padded to the console's width.
WIDE = 100_000


def _plain_list_types() -> None:
    """typer (0.2x) shows a repeatable argument's type as ``<list[Path]>`` after its
    ``voltages...`` name: shown as the element's type, ``<path>``, instead."""
    from typer import core

    shown = getattr(getattr(core, "_TyperParameter", None), "display_type", None)
    if shown is None or getattr(shown, "plain", False):
        return

    def display_type(self, ctx):
        return re.sub(r"list\[(\w+)\]", lambda m: m.group(1).lower(), shown(self, ctx))

    display_type.plain = True
    core._TyperParameter.display_type = display_type


_plain_list_types()


class _Interrupted(BaseException):
    """A Ctrl-C carried past typer, which turns a KeyboardInterrupt into ``Exit(130)``."""


class _Group(TyperGroup):
    """The app's command group, letting a Ctrl-C through as a KeyboardInterrupt.

    typer answers a KeyboardInterrupt with exit code 130 in its own ``main``.  For the
    command run from a shell :func:`main` gives that code too (after every ``finally``
    has run), but a caller that runs the app in-process (pytest's ``CliRunner``, a
    notebook) must see the interrupt itself: typer's ``Exit(130)`` made a test fail
    and the suite go on after a Ctrl-C.
    """

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except KeyboardInterrupt as stop:
            raise _Interrupted from stop

    def main(self, *args, **kwargs):
        try:
            return super().main(*args, **kwargs)
        except _Interrupted:
            raise KeyboardInterrupt from None

    def parse_args(self, ctx, args):
        """Refuse a number typed with digits of another script (``--tare \u0663``) before any
        option reads it: int() and float() read '\u0663' (Arabic-Indic three) as 3."""
        for i, token in enumerate(args):
            option, eq, value = token.partition("=") if token.startswith("-") else ("", "", token)
            if not eq:
                option, value = (args[i - 1] if i and args[i - 1].startswith("-") else ""), token
            bad = _other_digit(value) if _NUMBER_LIKE.fullmatch(value) else None
            if bad is not None:
                # named as Click names a bad value: the option, and the command's help
                command = self.get_command(ctx, args[0]) if args else None
                # typer bundles its own Click (no `click` package to import): its Context class
                where = type(ctx)(command, info_name=args[0], parent=ctx) if command else ctx
                raise typer.BadParameter(_other_digit_message(value, bad), ctx=where,
                                         param_hint=f"'{option}'" if option else None)
        return super().parse_args(ctx, args)


# a token that can only be a number (or numbers: --zero 1,2,3, --folds 1,2;3,4)
_NUMBER_LIKE = re.compile(r"[\d.,;:eE+\-]+")


def _other_digit(text: str) -> str | None:
    """The first digit of ``text`` that is not ASCII 0-9, if any."""
    return next((c for c in text if c.isdigit() and not c.isascii()), None)


def _other_digit_message(text: str, bad: str) -> str:
    head = "" if text == bad else f"{text!r}: "
    return f"{head}{bad!r} (U+{ord(bad):04X}) is not an ASCII digit 0-9"


app = typer.Typer(
    cls=_Group,
    add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
    # plain help: the rich formatter labels every flag "<bool>", as if it took a value
    rich_markup_mode=None,
    help="Static decoupling of multi-axis force sensors (three axes, six, or more gauges than "
         "components): the coupling error model of eq. (11), an eps-SVR per coupling.",
)


def _standard_streams() -> None:
    """A stream that the caller closed (``fsdecouple ... >&-``, a daemon without a
    terminal) reads and writes nothing instead of failing at the first print."""
    for name, mode in (("stdin", "r"), ("stdout", "w"), ("stderr", "w")):
        if getattr(sys, name) is None:
            setattr(sys, name, open(os.devnull, mode, encoding="utf-8"))  # noqa: SIM115
    # an ASCII locale (LC_ALL=POSIX without Python's UTF-8 mode) cannot encode the
    # gamma of a table header: tables show '?' in its place (one cell, so columns stay
    # aligned), error lines an escape (\u03b3, so no name is lost); never a traceback
    for stream, errors in ((sys.stdout, "replace"), (sys.stderr, "backslashreplace")):
        encoding = (getattr(stream, "encoding", None) or "").lower().replace("-", "")
        if encoding != "utf8" and hasattr(stream, "reconfigure"):
            with contextlib.suppress(ValueError, OSError):
                stream.reconfigure(errors=errors)


_standard_streams()


def _stdout_gone(stream=None) -> None:
    """Point stdout (or ``stream``) at /dev/null, so the interpreter's last flush cannot
    fail again."""
    with contextlib.suppress(OSError, ValueError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, (stream or sys.stdout).fileno())
        os.close(devnull)


def _last_flush(code: int) -> int:
    """Flush stdout and stderr before the interpreter does, and send a stream that cannot
    be written to /dev/null: without PYTHONUNBUFFERED (cron, systemd) an error line to a
    full stderr stayed in its buffer, and Python's own flush at exit made the code 120."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError) as err:
            _stdout_gone(stream)
            with contextlib.suppress(OSError, ValueError):
                stream.flush()  # what stayed in the buffer goes to /dev/null
            if code == 0 and isinstance(err, OSError):
                code = 128 + signal.SIGPIPE if isinstance(err, BrokenPipeError) else 2
    return code


def _literal(text, keep: str = ""):
    """A table's text (str or Text) with control characters escaped, before rich measures
    it: a newline in a sensor name stays in its cell, an ESC widens its column."""
    plain = text.plain if isinstance(text, Text) else text
    if not isinstance(plain, str) or plain.isprintable() or all(c in keep for c in plain
                                                                if not c.isprintable()):
        return text
    shown = printable(plain, keep=keep, spaces=True)
    return Text(shown, style=text.style, justify=text.justify) if isinstance(text, Text) else shown


def _literal_table(table: Table) -> Table:
    table.title, table.caption = _literal(table.title), _literal(table.caption)
    for col in table.columns:
        col.header = _literal(col.header, keep="\n")  # two-line headers are the table's own
        col._cells = [_literal(c) for c in col._cells]  # rich's cell list (private)
    return table


class _Console(Console):
    """Every piece of text shown is literal: control characters that are not the console's
    own (ESC, a clear-screen in a sensor name) are shown escaped, by
    :func:`~fsdecouple.errors.printable`, in tables and titles too (rich itself drops a
    carriage return or a bell).  A table's text is escaped before rich measures it, so a
    newline in a name stays in its cell and the table stays aligned; any other text is
    escaped as it is written (its own line breaks kept)."""

    def print(self, *objects, **kw) -> None:
        if not any(isinstance(o, Table) for o in objects):
            return super().print(*objects, **kw)
        for o in objects:  # a table wider than the terminal: in parts that fit, never cut
            if not isinstance(o, Table):
                super().print(o, **kw)
                continue
            table = _literal_table(o)
            if self.width < WIDE:  # a terminal: split to its width
                for part in fit_width(table, self):
                    super().print(part, **kw)
                continue
            # a file or a pipe (a CI log read with grep): never split, so each table stays
            # one; cells that may wrap do so at REDIRECTED columns (init's reasons)
            super().print(table, **{**kw, "width": max(REDIRECTED, needed_width(self, table))})

    def _render_buffer(self, buffer) -> str:  # rich's last step before writing (private)
        return super()._render_buffer(
            s if s.control or s.text == "\n" or s.text.isprintable()
            else Segment(printable(s.text, keep="\n", spaces=True), s.style, s.control)
            for s in buffer)

    def on_broken_pipe(self) -> None:
        """The reader of stdout went away (``| head``): exit 141, as after SIGPIPE, not
        rich's 1, which here means a failed gate."""
        _stdout_gone()
        raise SystemExit(128 + signal.SIGPIPE)


# No markup, no emoji codes and no highlighting: every name and cell from a user's
# file is printed literally (a sensor named ':thumbs_up:' or 'a[/]b' included, in
# table titles too).  Redirected output (a CI log) is not cut at 80 columns.
console = _Console(markup=False, emoji=False, highlight=False,
                  width=None if sys.stdout.isatty() else WIDE)
err_console = _Console(stderr=True, markup=False, emoji=False, highlight=False,
                      width=None if sys.stderr.isatty() else WIDE)

ConfigOpt = Annotated[
    Path | None,
    typer.Option("--config", "-c", help="YAML config (default: the paper's sensor)."),
]
# commands that take a model file: its own settings unless a config is given
ModelConfigOpt = Annotated[
    Path | None,
    typer.Option("--config", "-c", help="YAML config (default: the model's own settings)."),
]
ForceOpt = Annotated[bool, typer.Option("--force", help="Overwrite existing output files.")]


def _output_file(text: str) -> Path:
    # typer's Path would turn 'report/' into a file named 'report'
    if names_a_directory(text):
        raise typer.BadParameter(f"{printable(text)!r} names a directory, not the file to write")
    return Path(text)


def output_file(help: str):
    """The ``-o`` option of a command that writes one file: its name as typed, refused when it
    can only name a directory (``-o out/``), never silently written as a file ``out``."""
    return typer.Option("--output", "-o", help=help, parser=_output_file, metavar="<path>")
JsonOpt = Annotated[bool, typer.Option("--json", help="Print a JSON document on stdout.")]


@contextlib.contextmanager
def user_errors(flags: dict[str, str] | None = None):
    """Turn library errors into one red line on stderr and exit code 2.

    The line is one line whatever it quotes (control characters escaped, cut at
    MAX_MESSAGE characters).  numpy's RuntimeWarnings (overflow near 1e308) are
    not printed: the error, or the row's status, says what happened.

    An error about one argument (``err.argument``, its Python name) is prefixed by the
    flag the user typed: ``flags[argument]``, else typer's own spelling of the name
    (``gross_error`` -> ``--gross-error``); a message ending in a remedy (``err.remedy``)
    gets the flag that applies it.  The library speaks of the data; only here does a
    message learn the flag's name.
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            yield
    except FsdecoupleError as err:
        message = printable(err)
        if getattr(err, "argument", None):
            message = f"{flag_of(err.argument, flags)}: {message}"
        if getattr(err, "remedy", None):
            flag, value = flag_of(err.remedy[0], flags), printable(err.remedy[1])
            message = f"{message} with {flag} {value}".rstrip()
        if len(message) > MAX_MESSAGE:
            message = f"{message[:MAX_MESSAGE]}... (cut)"
        err_console.print(Text("error: ", "red") + Text(message), soft_wrap=True)
        raise typer.Exit(2) from None


MAX_MESSAGE = 1000


def flag_of(argument: str, flags: dict[str, str] | None = None) -> str:
    """The command-line flag of library argument ``argument`` (typer's spelling by default)."""
    return (flags or {}).get(argument) or "--" + argument.replace("_", "-")


def interactive() -> bool:
    """A progress bar's terminal: stderr is one (rich's own test also honours FORCE_COLOR
    and TTY_COMPATIBLE, which put the bar's escapes into a redirected log), and not CI."""
    return err_console.is_terminal and sys.stderr.isatty() and not os.environ.get("CI")


def say(lines, label: str = "error", style: str = "red") -> None:
    """Each line on stderr after a coloured ``label:`` (one per failed file, sensor or gate),
    one line whatever it quotes: a newline in a sensor's or a file's name is escaped."""
    for line in lines:
        err_console.print(Text(f"{label}: ", style) + Text(printable(line)), soft_wrap=True)


def warn(lines) -> None:
    say(lines, "warning", "yellow")


def print_json(doc) -> None:
    sys.stdout.write(json.dumps(doc, indent=2, sort_keys=True, allow_nan=False) + "\n")


def version_callback(value: bool) -> None:
    if value:
        console.print(f"fsdecouple {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: Annotated[
        bool, typer.Option("--version", callback=version_callback, is_eager=True,
                             help="Print the version and exit.")
    ] = False,
) -> None:
    pass


def _read(calib) -> list[Path]:
    """The files a calibration set was read from."""
    return [Path(f) for f, _ in calib.files]


def _given(*paths):
    return [p for p in paths if p is not None]


def ascii_digits(ctx: typer.Context, param: typer.CallbackParam, value):
    """An option holding numbers as text (``--folds``, ``--zero``, ``FILE:ROW``): its digits
    are ASCII.  Python's int() and float() read '٣' (Arabic-Indic three) as 3, so a digit
    the user may not have meant to type was obeyed; a token that is only a number is
    refused before parsing (``_Group.parse_args``)."""
    for text in value if isinstance(value, list | tuple) else [value]:
        number = text.rsplit(":", 1)[-1] if param.name == "exclude" and text else text
        bad = _other_digit(number or "")
        if bad is not None:
            raise typer.BadParameter(_other_digit_message(text, bad))
    return value


def _parse_zero(text: str) -> tuple[float, ...]:
    """``--zero``'s comma-separated finite outputs; their count is checked against the model
    (:func:`fsdecouple.logs.apply.check_options`), which knows its outputs."""
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if not values or not all(math.isfinite(v) for v in values):
        raise InputError(f"--zero {text!r}: expected the zero of each output, comma-separated "
                         "finite numbers, e.g. 0.01,-0.02,0")
    return values


def _bar(*columns) -> Progress:
    """A progress bar on stderr, drawn on a terminal only (never with CI set), erased when done."""
    # the console reads no markup (user text is literal), so the bar's own style is given
    # as a style, not as "[progress.description]" markup it would print as it stands
    description = TextColumn("{task.description}", style="progress.description", markup=False)
    return Progress(description, BarColumn(), *columns, console=err_console,
                    disable=not interactive(), transient=True)


class _CountOnceKnown(MofNCompleteColumn):
    """``done/total`` once the library has said how many steps there are; until then (or
    for good: fit without --tune reports no steps) the time elapsed, not a ``0/?`` that
    never moves."""

    def render(self, task):
        if task.total is None:
            return TimeElapsedColumn().render(task)
        return super().render(task)


@contextlib.contextmanager
def progress_bar(label: str, *columns):
    """:func:`_bar` with one task of unknown length; yields the ``progress(done, total)``
    callback that the library's long calls take."""
    columns = tuple(_CountOnceKnown() if type(c) is MofNCompleteColumn else c for c in columns)
    with _bar(*columns) as bar:
        task = bar.add_task(label, total=None)
        yield lambda done, total: bar.update(task, completed=done, total=total)


def show(doc: dict, table, json_out: bool) -> None:
    """A summary document: as JSON on stdout with ``--json``, else ``table(doc)``."""
    if json_out:
        print_json(doc)
    else:
        console.print(table(doc))


_stopped_by: list[int] = []  # the signal that stopped the command, once one has


def _terminate(signum, frame) -> None:
    # SIGTERM (kill, CI timeouts) unwinds like Ctrl-C, so temporary files are removed
    _stopped_by.append(signum)
    raise SystemExit(128 + signum)


def _cannot_write(err: OSError) -> int:
    """stdout or stderr failed (a full disk, a closed reader): exit 2 like any output that
    cannot be written, or 141 as after SIGPIPE when the reader went away (``| head``)."""
    _stdout_gone()
    if isinstance(err, BrokenPipeError):
        return 128 + signal.SIGPIPE
    with contextlib.suppress(OSError, ValueError):
        err_console.print(Text("error: ", "red") + Text(f"cannot write the output: {printable(err)}"),
                          soft_wrap=True)
    return 2


def main() -> None:
    _stopped_by.clear()  # a process may run the command more than once (tests, embedding)
    signal.signal(signal.SIGTERM, _terminate)
    # for the whole process, not only inside user_errors(): a pool's threads still running
    # after an error (cv --workers 2) warned on stderr once the error had restored the filters
    warnings.simplefilter("ignore", RuntimeWarning)
    try:
        code = _run()
    except KeyboardInterrupt:
        code = 128 + signal.SIGINT
    except SystemExit as stop:
        code = stop.code
    except OSError as err:  # a usage error's or a gate's line on a full or closed stderr
        code = _cannot_write(err) if not _stopped_by else 128 + _stopped_by[0]
    except BaseException:
        # the SystemExit the handler raised can come back as another exception, when it
        # was raised inside a library's callback into Python: a stop is still a stop (once
        # exit 1 with a traceback); the unwinding ran every finally block all the same
        if not _stopped_by:
            raise
        code = 128 + _stopped_by[0]
    if _stopped_by:  # a stop handled as an error on its way out (exit 2, or 1) is a stop
        code = 128 + _stopped_by[0]
    if code in (128 + signal.SIGINT, 128 + signal.SIGTERM):
        # stopped: every finally block has run (temporary files removed); threads still
        # inside libsvm or a thread pool's job are not waited for
        with contextlib.suppress(OSError, ValueError):
            sys.stdout.flush()
            sys.stderr.flush()
        os._exit(code)
    code = _last_flush(code if isinstance(code, int) else 0)
    # the process ends here: the interpreter's last cycle collection would walk every
    # object pandas, pyarrow and scipy made (0.15-0.2 s of CPU after cv on the sample)
    # to free memory the system takes back anyway; atexit handlers still run
    gc.freeze()
    sys.exit(code)


def _run() -> int:
    try:
        code = app(standalone_mode=False)
        sys.stdout.flush()
    except OSError as err:
        if getattr(err, "filename", None) is not None:  # a file's, not a standard stream's
            err_console.print(Text("error: ", "red") + Text(f"{printable(err.filename)}: "
                                                            f"{err.strerror or err}"), soft_wrap=True)
            return 2
        code = _cannot_write(err)
    except SystemExit:
        # Click answers a broken pipe with exit 1, the failed-gate code, after wrapping
        # stdout so that its last flush stays quiet; the reader went away: 141, as SIGPIPE
        if type(sys.stdout).__name__ != "PacifyFlushWrapper":
            raise
        code = _cannot_write(BrokenPipeError())
    except typer.Abort as abort:
        if isinstance(abort.__cause__ or abort.__context__, KeyboardInterrupt):
            return 128 + signal.SIGINT
        err_console.print(Text("error: ", "red") + Text("aborted"))
        code = 1
    except Exception as err:
        # Click's usage errors (a missing argument, `--tare abc`, an unknown
        # command) get one line like every other bad input, not a framed box
        if not (hasattr(err, "format_message") and hasattr(err, "exit_code")):
            raise
        if type(err).__name__ == "NoArgsIsHelpError":  # a bare `fsdecouple`: its help, as is
            sys.stderr.write(err.format_message() + "\n")
            return err.exit_code
        ctx = getattr(err, "ctx", None)
        command = ctx.command_path if ctx is not None else "fsdecouple"
        message = " ".join(err.format_message().split())
        if message:
            err_console.print(Text("error: ", "red") + Text(f"{command}: {message} (see '{command} --help')"),
                              highlight=False, soft_wrap=True)
        code = err.exit_code
    return code if isinstance(code, int) else 0
