"""Trained weights on disk: a ``.safetensors`` file of tensors and a ``.json`` sidecar of metadata sharing one stem
(the lifter's and the motion prior's), each written atomically."""

from __future__ import annotations

import os
import uuid
from pathlib import Path
from typing import Callable

__all__ = ["weights_pair_paths", "write_atomically"]


def weights_pair_paths(stem: str | Path) -> tuple[Path, Path]:
    """(``stem.safetensors``, ``stem.json``); ``stem`` may also be given with either suffix."""
    stem = Path(stem)
    if stem.suffix in (".safetensors", ".json"):
        stem = stem.with_suffix("")
    return stem.with_suffix(".safetensors"), stem.with_suffix(".json")


def write_atomically(path: Path, write: Callable[[Path], object]) -> None:
    """``write(temporary path)`` beside ``path``, then rename it onto ``path``: a reader never sees half a file,
    and a failed write leaves nothing behind. The file is made readable like any package file."""
    tmp = path.with_name(f".{path.name}.tmp-{uuid.uuid4().hex[:8]}")
    try:
        write(tmp)
        tmp.chmod(0o644)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
