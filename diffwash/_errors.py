"""Errors a user can act on: one line that names the file and the field."""

from __future__ import annotations

import os


class DiffwashError(Exception):
    """An error caused by the user's input, reported as one line.

    The command line prints it without a traceback and exits with `exit_code`
    (2: a usage error, bad input; 1: the work itself failed, e.g. a fit that did
    not converge).
    """

    exit_code = 2

    def __init__(self, message: str, *, file: str | os.PathLike | None = None, field: str | None = None):
        self.file = None if file is None else os.fspath(file)
        self.field = field
        self.problem = message
        prefix = ""
        if self.file is not None:
            prefix += f"{self.file}: "
        if field is not None:
            prefix += f"{field}: "
        super().__init__(_one_line(prefix + message))


def _one_line(text: str) -> str:
    """`text` with line breaks and other control characters (from a file's keys or names) escaped: one line."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)


class FailureError(DiffwashError):
    """The input was fine but the work failed (e.g. a fit that did not converge)."""

    exit_code = 1
