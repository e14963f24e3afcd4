"""The one error type users see: a message, and the parameter it is about."""

from __future__ import annotations

import re

NAMED = re.compile(r"`([a-z][a-z0-9_]*)`")
"""A parameter's name in a message: in backticks (```n_flips```)."""


class CredcliError(ValueError):
    """A user-facing error: bad input or a bad setting.

    A ``ValueError``, so that Python callers can catch it as the bad value it reports.
    Library code raises it and never prints; exit codes exist only at the command line's
    edge (2 for this error).

    Parameters
    ----------
    message : str
        What was wrong and where. It names parameters in backticks (```n_flips` 5 is too
        few``); the command line shows each as its flag (``--flips``), a config file's
        table as its key.
    parameter : str, optional
        The argument or setting at fault (``"cov"``, ``"n_flips"``) when there is one.

    Attributes
    ----------
    message : str
        The message, as given.
    parameter : str or None
        The argument or setting at fault, or None.

    Examples
    --------
    >>> from credcli import DiagnosisConfig
    >>> try:
    ...     DiagnosisConfig(alpha=2)
    ... except CredcliError as error:
    ...     print(error.parameter, "|", error)
    alpha | invalid setting: `alpha` must be in (0, 1)
    """

    def __init__(self, message: str, parameter: str | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.parameter = parameter

    def __reduce__(self):
        """Pickled whole (message and parameter), as worker processes send it back."""
        return (type(self), (self.message, self.parameter))


_ESCAPES = {"\n": "\\n", "\r": "\\r", "\t": "\\t"}
_CONTROL = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029\ud800-\udfff]")


def printable(text: str) -> str:
    """``text`` made safe to show on a terminal or in a one-line message.

    Every control character (C0, DEL, C1, the Unicode line and paragraph separators) and
    every lone surrogate (a file name's bytes that are not UTF-8) becomes a backslash
    escape (``\\n``, ``\\x1b``), as git and ls quote names, so that a name from the data
    can neither move the cursor, set a window title, nor start a line of its own.

    Parameters
    ----------
    text : str
        Any text, typically a name or value taken from the data.

    Returns
    -------
    str
        ``text`` itself when it has no such character, else ``text`` with each one
        escaped: ``\\n``, ``\\r``, ``\\t``, ``\\xNN`` below U+0100, ``\\uNNNN``
        from there on.

    Examples
    --------
    >>> print(printable("run\\n1\\x1b[2J"))
    run\\n1\\x1b[2J
    """
    if _CONTROL.search(text) is None:
        return text
    return _CONTROL.sub(
        lambda m: (
            _ESCAPES.get(m.group(), f"\\x{ord(m.group()):02x}")
            if ord(m.group()) < 0x100
            else f"\\u{ord(m.group()):04x}"
        ),
        text,
    )


NAME_LIMIT = 80
"""Most characters of a name from the data shown in a one-line verdict (:func:`shortened`)."""


def shortened(name: str, limit: int = NAME_LIMIT) -> str:
    """A name from the data cut in the middle for a one-line message: past ``limit``
    characters, its first ``limit − 40`` and last 39 around an ellipsis, and its length
    (``credcli.io.files.shown`` cuts an escaped file name so).

    Parameters
    ----------
    name : str
        A segment's or file's name.
    limit : int, default NAME_LIMIT
        The longest name shown whole (at least 41).

    Returns
    -------
    str
        ``name``, or its start and end with ``(N characters)``.

    Examples
    --------
    >>> shortened("a" * 30 + "b" * 70, 50)
    'aaaaaaaaaa…bbbbbbbbbbbbbbbbbbbbbbbbbbbbbbbbbbbbbbb (100 characters)'
    """
    if len(name) <= limit:
        return name
    return f"{name[: limit - 40]}…{name[-39:]} ({len(name):,} characters)"


def plain(message: str) -> str:
    """A message with its parameter names out of their backticks.

    Parameters
    ----------
    message : str
        A message that names parameters in backticks (``NAMED``), as a
        ``CredcliError``'s does.

    Returns
    -------
    str
        The message with each backticked name (lower case, digits, underscores) bare.

    Examples
    --------
    >>> plain("`n_flips` must be a positive integer")
    'n_flips must be a positive integer'
    """
    return NAMED.sub(r"\1", message)
