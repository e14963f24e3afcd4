"""The one error type users see: a message, and the parameter it is about."""

from __future__ import annotations


class CredcliError(ValueError):
    """A user-facing error: bad input or a bad setting. A ``ValueError``, so that Python
    callers can catch it as the bad value it reports.

    ``parameter`` names the argument or setting at fault (``"cov"``, ``"n_flips"``) when
    there is one; the command line turns it into its flag. Library code raises it and never
    prints; exit codes exist only at the command line's edge (2 for this error).
    """

    def __init__(self, message: str, parameter: str | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.parameter = parameter

    def __reduce__(self):
        """Pickled whole (message and parameter), as worker processes send it back."""
        return (type(self), (self.message, self.parameter))
