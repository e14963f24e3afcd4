"""The one error type users see: a message for stderr and an exit code."""

from __future__ import annotations


class CredcliError(Exception):
    """A user-facing error: bad input, bad option, or a regression-free usage problem.

    The CLI turns it into one line on stderr and ``exit_code`` (2 by default).
    Library code raises it; it never prints.
    """

    def __init__(self, message: str, exit_code: int = 2) -> None:
        super().__init__(message)
        self.message = message
        self.exit_code = exit_code

    def __reduce__(self):
        """Pickled whole (message and exit code), as worker processes send it back."""
        return (type(self), (self.message, self.exit_code))
