"""File helpers shared by the readers and writers: atomic writes, JSON loading with clear errors."""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

from humancal.formats.errors import FormatError

__all__ = ["atomic_write_with", "atomic_write_text", "atomic_write_texts", "read_text", "load_json"]


def atomic_write_with(path: str | Path, write: Callable[[BinaryIO], object]) -> Path:
    """Write a file atomically: ``write(handle)`` fills a temporary file in the same folder, then ``os.replace``.

    A failure at any point leaves ``path`` as it was (absent or with its previous content) and removes the
    temporary file. The parent folder is created when missing; the file gets the ordinary permissions (umask).

    Returns:
        The path written.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            write(handle)
            handle.flush()
            os.fsync(handle.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp_name, 0o666 & ~umask)  # mkstemp makes it private; a written file is an ordinary one
        os.replace(tmp_name, path)
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise
    return path


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8, ``\n`` line ends) to ``path`` atomically (see :func:`atomic_write_with`)."""
    return atomic_write_with(path, lambda handle: handle.write(text.encode("utf-8")))


def atomic_write_texts(texts_by_path: dict[Path, str]) -> list[Path]:
    """Write several files, each atomically (see :func:`atomic_write_text`), in the given order.

    Callers build every text first, so that an invalid input raises before any file is touched.
    """
    return [atomic_write_text(path, text) for path, text in texts_by_path.items()]


def read_text(path: str | Path) -> str:
    """The UTF-8 text of ``path``.

    Raises:
        FileNotFoundError: the file does not exist.
        FormatError: the file is not valid UTF-8 text.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as err:
        raise FormatError(path, None, "UTF-8 text", f"undecodable byte at offset {err.start}") from None


def load_json(path: str | Path) -> object:
    """Parse the JSON file ``path``.

    Raises:
        FileNotFoundError: the file does not exist.
        FormatError: the file is not valid JSON (truncated, malformed), with line and column.
    """
    text = read_text(path)
    try:
        return json.loads(text)
    except json.JSONDecodeError as err:
        raise FormatError(path, None, "valid JSON", f"{err.msg} at line {err.lineno} column {err.colno}") from None
