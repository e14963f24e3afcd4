"""Parameter names as the command line spells them: ``max_dt`` is ``--max-dt``.

The library names parameters in backticks in its errors and notes (```max_dt` 0.05 s``),
so that a Python caller reads the names of its own arguments. The command line's edge
(:mod:`credcli.cli.edge`) knows every option of every command and registers the map here
once (:func:`use`); what the CLI shows, errors and notes alike, passes through
:func:`flag_names`.
"""

from __future__ import annotations

from collections.abc import Callable

from credcli.errors import NAMED

_source: list[Callable[[], dict[str, str]]] = []


def use(flags: Callable[[], dict[str, str]]) -> None:
    """Register how to get parameter name -> flag (called once, by the edge).

    Parameters
    ----------
    flags : callable
        Called with no argument when a message is shown; returns the map of parameter
        name -> flag (``{"n_flips": "--flips", ...}``). It replaces any earlier one.
    """
    _source[:] = [flags]


def flag_names(message: str) -> str:
    """``message`` with each backticked parameter name as its flag (```n_flips` 5`` ->
    ``--flips 5``); a name that is no option keeps its backticks. Unchanged until the
    edge has registered the command line's options.

    Parameters
    ----------
    message : str
        An error, note or verdict of the library.

    Returns
    -------
    str
        The message as the command line says it.
    """
    if not _source or "`" not in message:
        return message
    flags = _source[0]()
    return NAMED.sub(lambda m: flags.get(m[1], m[0]), message)
