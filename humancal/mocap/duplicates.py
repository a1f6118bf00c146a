"""Mocap files whose content is the same: a dataset may ship one take under two names.

The CMU data root has one such pair (``14_31`` and ``14_36`` are byte-identical): a clip counted twice weighs twice
in a held-out figure and in its subject's shape fit. :func:`identical_files` finds such groups so that the caller
can say so; it does not decide which name is right.
"""

from __future__ import annotations

import gzip
import hashlib
from collections.abc import Sequence
from pathlib import Path

from humancal.mocap.clip import MocapFormatError

__all__ = ["identical_files"]

_CHUNK = 1 << 20


def _content_digest(path: Path) -> str:
    """SHA-256 of the file's content, decompressed first when the name ends in ``.gz``."""
    digest = hashlib.sha256()
    opener = gzip.open if path.suffix == ".gz" else open
    try:
        with opener(path, "rb") as stream:
            while chunk := stream.read(_CHUNK):
                digest.update(chunk)
    except (gzip.BadGzipFile, EOFError) as err:
        raise MocapFormatError(path, None, f"a .gz name, but not a whole gzip stream ({err})") from err
    return digest.hexdigest()


def identical_files(paths: Sequence[Path | str]) -> list[tuple[Path, ...]]:
    """Groups of two or more files with the same content.

    Args:
        paths: files to compare; ``.gz`` files are compared by their decompressed content, so ``a.bvh`` and a
            gzipped copy ``b.bvh.gz`` are the same take.

    Returns:
        One tuple per group, its files in the order given (the first is the one a caller would keep); the groups
        in the order of their first file. Empty when every file is distinct.

    Raises:
        MocapFormatError: a ``.gz`` file that is not gzip or is cut short (the message names it).
        OSError: a file cannot be read (missing, no permission).
    """
    groups: dict[str, list[Path]] = {}
    for path in map(Path, paths):
        groups.setdefault(_content_digest(path), []).append(path)
    return [tuple(group) for group in groups.values() if len(group) > 1]
