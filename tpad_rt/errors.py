"""The exceptions tpad-rt raises for things a user can fix.

Every error a user can cause (a bad file, URL, flag or missing component) is a
:class:`TpadError`; the CLI prints its message on one line and exits 1.
"""

from __future__ import annotations

import unicodedata


class TpadError(Exception):
    """Base class of every user-facing tpad-rt error; its message is complete."""


class ConfigError(TpadError):
    """A texture or device file, or a value given for one, is invalid.

    ``errors`` holds one breadcrumb line per problem, each of the form
    ``<file>: <path.to[1].key>: <what is wrong>`` (the file part is omitted
    when there is no file). ``str(err)`` joins them with newlines.
    """

    def __init__(self, errors: list[str] | str):
        self.errors: list[str] = [errors] if isinstance(errors, str) else list(errors)
        super().__init__("\n".join(self.errors))


class BackendError(TpadError):
    """An input or output backend could not be opened or failed while running."""


class SampleError(TpadError, ValueError):
    """A finger sample (or another value handed to the renderer at run time) is out of its range.

    A ValueError for API users and a TpadError for the command line: the message names
    the argument, the accepted range and the value (``x_mm: must be a finite number in
    [-130, 260] mm, got nan``).
    """


def printable(text: str) -> str:
    """``text`` with control characters (NUL, newline, escape...) written as ``\\xNN``, for one-line messages."""
    return "".join(f"\\x{ord(char):02x}" if unicodedata.category(char) == "Cc" else char for char in text)
