"""The command line's outer edge: run the app, and turn every outcome into an exit code
and one line on stderr. The only place that knows exit codes.

0 ok; 1 a regression verdict (gate, --fail-on); 2 bad input or usage; 3 an internal error
(the traceback with --debug); 130 interrupted; 128 + N on signal N.
"""

from __future__ import annotations

import codecs
import errno
import functools
import os
import signal
import sys
import traceback
import warnings

import typer

from credcli.cli import flags
from credcli.cli.app import app
from credcli.cli.flags import flag_names
from credcli.cli.options import FIELD_OPTIONS
from credcli.errors import CredcliError, printable


def _click_exception_types() -> tuple[type, ...]:
    """Click's exception base: vendored by typer >= 0.2x, the click package before."""
    types: list[type] = []
    try:
        from typer._click.exceptions import ClickException as Vendored

        types.append(Vendored)
    except ImportError:
        pass
    try:
        from click import ClickException

        types.append(ClickException)
    except ImportError:
        pass
    return tuple(types)


def main(argv: list[str] | None = None) -> int:
    """Entry point: run the app and turn every outcome into an exit code.

    Warnings (numpy's among them) are never printed raw: each distinct one becomes a
    ``credcli: note:`` line on stderr at the end, with its source under --debug; a run
    that ends in an error (exit 2 or 3) shows its one line only, the notes under --debug.

    Parameters
    ----------
    argv : list of str or None, optional
        The arguments after the program's name; None for ``sys.argv[1:]``.

    Returns
    -------
    int
        The exit code: 0 ok; 1 a regression verdict (gate, --fail-on); 2 bad input or
        usage, one line on stderr; 3 an internal error, one line (the traceback with
        --debug); 130 interrupted; 128 + N on signal N (SIGTERM, SIGHUP).
    """
    from credcli.schedule.pool import keep_freed_memory, single_threaded_blas

    single_threaded_blas()  # before numpy loads; a user's own setting wins
    _terminate_on_signals()
    args = list(sys.argv[1:] if argv is None else argv)
    if "--help" not in args and not app_commands().isdisjoint(args):
        keep_freed_memory()  # this process is credcli's own: it may tune its allocator
    debug = (
        "--debug" in args[: next((i for i, a in enumerate(args) if a in app_commands()), len(args))]
    )
    command = _command()
    code = 3
    strict = _escape_unencodable()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            code = _run(command, args, debug)
        finally:  # an error is one line: the notes of a run it ended only under --debug
            if code in (0, 1) or debug:
                note_warnings(caught, debug)
            for stream, errors in strict:
                stream.reconfigure(errors=errors)
    return code


def _escape_unencodable() -> list:
    """stdout and stderr write what their encoding cannot (× under LC_ALL=C, a file name's
    undecodable bytes under a strict UTF-8 locale) as backslash escapes, not as exit 3;
    returns the streams changed and their handlers, to be restored. A UTF-8 stream that
    writes undecodable bytes back as they were (surrogateescape, Linux's C.UTF-8) stays so."""
    changed = []
    for stream in (sys.stdout, sys.stderr):
        errors, encoding = getattr(stream, "errors", None), getattr(stream, "encoding", None)
        try:
            utf8 = codecs.lookup(encoding or "").name == "utf-8"
        except LookupError:
            utf8 = False
        if not hasattr(stream, "reconfigure") or errors == "backslashreplace":
            continue
        if errors == "strict" or (errors == "surrogateescape" and not utf8):
            try:
                stream.reconfigure(errors="backslashreplace")
            except (ValueError, OSError):  # a closed or detached stream
                continue
            changed.append((stream, errors))
    return changed


class Terminated(BaseException):
    """SIGTERM or SIGHUP arrived: unwinds like Ctrl-C (temporary files removed, workers
    stopped), but is not a KeyboardInterrupt, which Click would report as an abort."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum


def _terminate_on_signals() -> None:
    """SIGTERM and SIGHUP end a run as Ctrl-C does, with exit 128 + the signal's number."""

    def handler(signum, frame):
        raise Terminated(signum)

    for name in ("SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), handler)


def app_commands() -> set[str]:
    """The names of the app's commands.

    Returns
    -------
    set of str
        Each registered command's name (``diagnose``, ``gate``, …).
    """
    return {c.name or c.callback.__name__ for c in app.registered_commands}


_LIBRARY_CHATTER = (DeprecationWarning, PendingDeprecationWarning, FutureWarning, ResourceWarning)
"""Warnings meant for a library's own callers or developers, shown only under --debug:
Python hides ResourceWarning by default (a signal during an import can leave an unclosed
.pyc file, whose warning would be a second stderr line after 'credcli: terminated')."""


def note_warnings(caught, debug: bool) -> None:
    """Each distinct warning once, as a ``credcli: note:`` line. numpy's floating-point
    warnings ("overflow encountered in matmul") are one line in the user's terms, with
    numpy's words in brackets; where they came from only under --debug.

    Parameters
    ----------
    caught : list of warnings.WarningMessage
        The warnings recorded during the run.
    debug : bool
        ``--debug``: also show each warning's file and line, and the deprecation,
        future and resource warnings meant for a library's developers.
    """
    seen: dict[str, None] = {}
    floating: dict[str, None] = {}
    for w in caught:
        if issubclass(w.category, _LIBRARY_CHATTER) and not debug:
            continue  # a library's notice to its own callers, not about the user's data
        message = str(w.message).splitlines()[0] if str(w.message) else ""
        where = f" ({w.filename}:{w.lineno})" if debug else ""
        if issubclass(w.category, RuntimeWarning) and " encountered in " in message:
            floating[message + where] = None
        else:
            seen[f"{w.category.__name__}: {message}{where}"] = None
    if floating:
        print(
            "credcli: note: some numbers overflowed or were undefined while computing "
            f"({'; '.join(floating)}); the errors may be far outside the range of their "
            "claimed covariances, so read the affected figures with care",
            file=sys.stderr,
        )
    for text in seen:  # a library's warning may quote the data (matplotlib: a name's glyph)
        print(f"credcli: note: {printable(text)}", file=sys.stderr)


def _run(command, args: list[str], debug: bool) -> int:
    try:
        result = command.main(args=args, prog_name="credcli", standalone_mode=False)
    except CredcliError as exc:
        _traceback(debug)
        print(f"credcli: error: {one_line(flag_names(exc.message))}", file=sys.stderr)
        return 2
    except _click_exception_types() as exc:
        ctx = getattr(exc, "ctx", None)
        if type(exc).__name__ == "NoArgsIsHelpError" and ctx is not None:
            help_text = exc.format_message()  # empty when Rich has printed the help panels
            if help_text:
                print(help_text)
            return 0
        hint = f" (see 'credcli {ctx.info_name} --help')" if ctx is not None and ctx.parent else ""
        print(f"credcli: error: {exc.format_message()}{hint}", file=sys.stderr)
        return 2 if getattr(exc, "exit_code", 2) in (1, 2) else exc.exit_code
    except Terminated as exc:
        print(f"credcli: terminated ({signal.Signals(exc.signum).name})", file=sys.stderr)
        return 128 + exc.signum
    except (typer.Abort, KeyboardInterrupt) as exc:
        if isinstance(exc.__context__, EOFError):  # Click turns an EOFError into an Abort
            _traceback(debug)
            print(
                "credcli: error: an input ended early (a truncated compressed file?)",
                file=sys.stderr,
            )
            return 2
        print("credcli: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        _silence_stdout()
        return 0
    except SystemExit as exc:  # Typer's answer to a closed pipe (EPIPE) is sys.exit(1)
        if exc.code == 1:
            _silence_stdout()
            return 0
        return int(exc.code or 0)
    except OSError as exc:
        from credcli.io.files import USER_ERRNOS, describe_os_error

        if exc.errno not in USER_ERRNOS:
            return _internal_error(exc, debug)
        _traceback(debug)
        if exc.filename is None and exc.errno == errno.ENOSPC:
            _silence_stdout()  # so that Python's own flush at exit does not fail again
        print(f"credcli: error: {describe_os_error(exc)}", file=sys.stderr)
        return 2
    except MemoryError as exc:
        if not _raised_by_credcli(exc):  # a library's (Dask reading a bad frame, say)
            return _internal_error(exc, debug)
        _traceback(debug)
        print(
            "credcli: error: not enough memory for this run; use fewer --flips, a smaller "
            "--max-elt-epochs or shorter segments",
            file=sys.stderr,
        )
        return 2
    except Exception as exc:  # noqa: BLE001 (the outer edge: one line, or the traceback)
        return _internal_error(exc, debug)
    if result == 130:  # Typer turns KeyboardInterrupt into a silent Exit(130)
        print("credcli: interrupted", file=sys.stderr)
    return int(result or 0)


def _raised_by_credcli(exc: BaseException) -> bool:
    """Whether the innermost frame of the traceback is credcli's own code (an allocation
    of ours, sized by the user's settings)."""
    tb = exc.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    return tb is not None and os.path.abspath(tb.tb_frame.f_code.co_filename).startswith(package)


def _internal_error(exc: BaseException, debug: bool) -> int:
    from credcli.io.files import shown

    _traceback(debug)
    first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    print(
        f"credcli: internal error: {type(exc).__name__}{': ' + shown(first, 300) if first else ''}"
        "; run with --debug for the traceback",
        file=sys.stderr,
    )
    return 3


@functools.cache
def _command():
    """The app's Click command, built once per process: Typer reads every command's
    signature and type hints to build it (about 15 ms), which a process that calls
    :func:`main` many times (a notebook's, the test suite's 900 runs) paid on each call.
    Click keeps nothing of a run on the command (each run has a Context of its own)."""
    return typer.main.get_command(app)


@functools.cache
def _flags() -> dict[str, str]:
    """Parameter name -> flag, for every option of every command, and for the settings
    fields that an option of another name sets (``n_flips`` is ``--flips``)."""
    flags: dict[str, str] = {}
    for command in _command().commands.values():
        for param in command.params:
            if getattr(param, "param_type_name", "") == "option":
                flags.setdefault(param.name, next(o for o in param.opts if o.startswith("--")))
    return flags | {field: flags[option] for field, option in FIELD_OPTIONS.items()}


flags.use(_flags)


def one_line(message: str) -> str:
    """A message as one line: a newline or any other control character in it (a file
    name's, a segment's, a library's) is escaped (:func:`credcli.errors.printable`), and
    past :data:`MAX_LINE` characters its middle is cut (an error line stays readable
    whatever the input holds).

    Parameters
    ----------
    message : str
        An error message.

    Returns
    -------
    str
        The escaped message; past `MAX_LINE` characters its first ``MAX_LINE - 160`` and
        last 120 characters around `` … ``, with the full length in brackets.
    """
    text = printable(message)
    if len(text) <= MAX_LINE:
        return text
    return f"{text[: MAX_LINE - 160]} … {text[-120:]} ({len(text):,} characters)"


MAX_LINE = 560
"""Longest message of an error line, so that with its `credcli: error: ` prefix the line
stays under 600 characters."""


def _traceback(debug: bool) -> None:
    if debug:
        traceback.print_exc()


def _silence_stdout() -> None:
    """After a closed pipe (credcli … | head), stop Python from failing again at exit."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


def entry() -> None:
    """The ``credcli`` console script: `main` on ``sys.argv``, its code as the exit status."""
    sys.exit(main())
