"""Error types shared by every layer: invalid input (exit 2) and failed analysis (exit 1)."""
from __future__ import annotations


class MechsysError(Exception):
    """Base class of the errors mechsys reports to users without a traceback."""

    exit_code = 1


class InputError(MechsysError):
    """Invalid input, reported as ``FILE:LINE:COL: key.path: message`` (exit code 2)."""

    exit_code = 2

    def __init__(self, message: str, file: str | None = None, line: int | None = None,
                 col: int | None = None, path: str | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.file = file
        self.line = line
        self.col = col
        self.path = path

    def __str__(self) -> str:
        where = ""
        if self.file:
            where = f"{self.file}:{self.line or 1}:{self.col or 1}: "
        key = f"{self.path}: " if self.path else ""
        text = f"{where}{key}{self.message}"
        # one line, whatever the file contained: escape line breaks and other control characters
        return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)


class AnalysisError(MechsysError):
    """An analysis that could not produce a result (no convergence, singular system...)."""

    exit_code = 1
