"""The one error type users see: a message, and the parameter it is about."""

from __future__ import annotations

import re

NAMED = re.compile(r"`([a-z][a-z0-9_]*)`")
"""A parameter's name in a message: in backticks (```n_flips```)."""


class CredcliError(ValueError):
    """A user-facing error: bad input or a bad setting. A ``ValueError``, so that Python
    callers can catch it as the bad value it reports.

    ``parameter`` names the argument or setting at fault (``"cov"``, ``"n_flips"``) when
    there is one. The message names parameters in backticks (```n_flips` 5 is too few``);
    the command line shows each as its flag (``--flips``), a config file's table as its
    key. Library code raises it and never prints; exit codes exist only at the command
    line's edge (2 for this error).
    """

    def __init__(self, message: str, parameter: str | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.parameter = parameter

    def __reduce__(self):
        """Pickled whole (message and parameter), as worker processes send it back."""
        return (type(self), (self.message, self.parameter))


def plain(message: str) -> str:
    """A message with its parameter names out of their backticks."""
    return NAMED.sub(r"\1", message)
