"""The exception hierarchy of brdffit.

Every error the library raises on purpose derives from :class:`BRDFError`, so a caller can
catch one class. Messages name the file (when there is one), what was expected and what was
found.
"""

from __future__ import annotations

__all__ = ["BRDFError", "BRDFFormatError", "FitError", "ExportError"]


class BRDFError(Exception):
    """Base class of every error raised by brdffit."""


class BRDFFormatError(BRDFError, ValueError):
    """A file or in-memory table does not follow the format it claims.

    Parameters
    ----------
    path:
        The offending file (or ``None`` for in-memory data).
    problem:
        What was expected and what was found.
    """

    def __init__(self, path, problem: str):
        self.path = None if path is None else str(path)
        self.problem = problem
        super().__init__(f"{_printable(self.path)}: {problem}" if self.path else problem)


def _printable(text: str) -> str:
    """``text`` with control characters, line separators and undecodable bytes escaped
    (``\\n``, ``\\x1b``, ``\\udcff``), so that a hostile file name keeps a message on one line."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() or c == " " else c.encode("unicode_escape",
                                                                   "backslashreplace").decode()
                   for c in text)


#: ``text`` made safe for one line of a terminal or a log: control characters, line
#: separators, bidirectional overrides and other invisible format characters escaped.
printable = _printable


def csv_cell(value):
    """A value for a CSV file opened by people: text :func:`printable`, and a cell that a
    spreadsheet would run as a formula (``=``, ``+``, ``-``, ``@`` first, then not a
    number) prefixed with ``'``; numbers and ``None`` unchanged."""
    if not isinstance(value, str):
        return value
    text = _printable(value)
    if text[:1] in ("=", "+", "-", "@"):
        try:
            float(text)
        except ValueError:
            return "'" + text
    return text


class FitError(BRDFError, RuntimeError):
    """A fit could not produce a valid model (no convergence, no valid data, NaN...)."""


class ExportError(BRDFError):
    """A fitted model cannot be written in the requested target format."""
