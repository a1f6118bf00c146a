"""The one error type of the format readers and writers."""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["FormatError", "missing_field", "short_repr"]


class FormatError(ValueError):
    """A file (or a value about to be written) does not have the expected form.

    The message is one line naming the file, the field, what was expected and what was found, e.g.
    ``calibration.json: field '2.RT': expected 12 numbers (row-major 3x4 [R|t]), got 9 values``.

    Attributes:
        path: the file (or folder) concerned, or ``None`` when the input is not a file.
        field: the field within it (dotted key path, joint, camera), or ``None``.
    """

    def __init__(self, path: str | Path | None, field: str | None, expected: str, got: object = None) -> None:
        """Build the message.

        Args:
            path: file or folder concerned (``None``: an in-memory input).
            field: field concerned (``None``: the file as a whole).
            expected: what the field should hold, in words ("12 numbers", "a JSON object").
            got: what was found: a string is quoted as is (a description such as ``"9 values"``), any other
                value is shown by its (shortened, one-line) ``repr``; ``None`` leaves the "got" part out.
        """
        self.path = None if path is None else str(path)
        self.field = field
        where = self.path if self.path is not None else "<input>"
        what = f"field '{field}': " if field else ""
        found = "" if got is None else f", got {got if isinstance(got, str) else short_repr(got)}"
        message = f"{where}: {what}expected {expected}{found}"
        super().__init__(message.replace("\r", " ").replace("\n", " "))


def short_repr(value: object, limit: int = 120) -> str:
    """A one-line ``repr`` of ``value``, at most ``limit`` characters (arrays shown as nested lists)."""
    if isinstance(value, (np.ndarray, np.generic)):
        value = value.tolist()
    text = " ".join(repr(value).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def missing_field(path: str | Path | None, field: str) -> FormatError:
    """The error for a required field that is absent."""
    return FormatError(path, field, "a value (the field is required)", "nothing")
