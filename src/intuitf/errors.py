"""Errors a user can cause, each with a message that says what happened and what to do.

The command line catches :class:`IntuitfError` and prints its message without a traceback.
"""

from __future__ import annotations


class IntuitfError(Exception):
    """Base class for errors caused by input, configuration or the environment.

    ``hint`` tells the user what to do about it.
    """

    def __init__(self, message: str, hint: str | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.hint = hint

    def __str__(self) -> str:
        return self.message if not self.hint else f"{self.message}\n  What to do: {self.hint}"


class VolumeError(IntuitfError):
    """A volume could not be read or is unusable."""


class TransferFunctionError(IntuitfError):
    """A transfer function is invalid or could not be read."""


class RenderError(IntuitfError):
    """Rendering parameters are invalid."""


class JudgeError(IntuitfError):
    """A judge is misconfigured or its server cannot be used."""


class BudgetExhausted(IntuitfError):
    """The call or money budget is spent; everything paid for so far is kept."""


class SessionError(IntuitfError):
    """A run cannot be started, continued or driven as asked (the base of the run errors below:
    catching it catches them all)."""


class RunLocked(SessionError):
    """Another process (or another session in this one) drives the run folder."""


class RunBusy(SessionError):
    """The run is going already (a front end asked to start it a second time)."""


class TooManyRuns(SessionError):
    """As many runs are going as the server allows; another waits until one ends."""


class StorageError(SessionError):
    """The run folder cannot be read or written: missing, corrupt, unwritable or a full disk.
    Everything written before it stays; the run continues with a resume once it is fixed."""


class RunCancelled(IntuitfError):
    """A person cancelled the run; the generation in progress is replayed when it goes on."""
