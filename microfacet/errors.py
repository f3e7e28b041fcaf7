"""Exception types for user errors."""

from __future__ import annotations

__all__ = ["InputError"]


class InputError(ValueError):
    """Bad user input (a file, key or argument); the message names what is at fault.

    The command line reports it as one line and exits with status 2.
    """
