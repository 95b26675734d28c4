"""Errors a person can act on.

Anything raised as :class:`UserError` reaches the command line as a short message
(file, line, column where known, what is wrong and what to do) and exit code 2,
never as a traceback.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class UserError(Exception):
    """A problem with the user's input, reported without a traceback.

    ``message`` says what is wrong and, where possible, how to fix it. ``location``
    is ``file:line:column`` (or as much of it as is known).
    """

    message: str
    location: str | None = None
    exit_code: int = 2

    def __str__(self) -> str:
        return f"{self.location}: {self.message}" if self.location else self.message
