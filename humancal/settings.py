"""Where humancal reads external data and keeps its own state.

Two settings, both environment variables so that a notebook, the CLI and Dagster agree:

``HUMANCAL_DATA_DIR``
    Root of external datasets (CMU mocap, Shelf, Human3.6M cameras; see the README's "Data" section).
    Default: ``../shared/data`` beside the repository checkout, when that folder exists.
``HUMANCAL_STATE_DIR``
    humancal's own state: materialized artifacts, the Dagster instance, the body-model cache.
    Default: ``.humancal`` inside the repository checkout (ignored by git).
"""

from __future__ import annotations

import os
from pathlib import Path

DATA_DIR_ENV = "HUMANCAL_DATA_DIR"
STATE_DIR_ENV = "HUMANCAL_STATE_DIR"

REPO_ROOT = Path(__file__).resolve().parent.parent
"""The checkout holding this package (an editable install keeps the package in the checkout)."""


class DataRootError(FileNotFoundError):
    """A dataset needs the data root and it is not set or does not hold the dataset."""


def data_root(required_for: str | None = None) -> Path | None:
    """The external data root, or ``None`` when neither the variable nor the default exists.

    Args:
        required_for: when given (e.g. ``"dataset 'shelf'"``), a missing root raises instead of
            returning ``None``, and the message says what needed it.

    Raises:
        DataRootError: naming ``HUMANCAL_DATA_DIR`` and what to set it to.
    """
    configured = os.environ.get(DATA_DIR_ENV)
    if configured:
        root = Path(configured).expanduser()
        if root.is_dir():
            return root
        if required_for:
            raise DataRootError(
                f"{DATA_DIR_ENV}={configured!r} is not a directory; {required_for} needs it to point at the "
                "folder holding cmu_mocap/, shelf_4dassoc/, h36m_cameras/"
            )
        return None
    default = REPO_ROOT.parent / "shared" / "data"
    if default.is_dir():
        return default
    if required_for:
        raise DataRootError(
            f"{required_for} needs external data: set {DATA_DIR_ENV} to the folder holding "
            "cmu_mocap/, shelf_4dassoc/, h36m_cameras/ (no default folder ../shared/data beside the checkout)"
        )
    return None


def dataset_dir(name: str, required_for: str | None = None) -> Path:
    """``<data root>/<name>``, checked to exist.

    Raises:
        DataRootError: the root is missing, or it lacks the folder ``name``.
    """
    why = required_for or f"dataset folder '{name}'"
    root = data_root(required_for=why)
    assert root is not None  # data_root raises when required_for is set
    path = root / name
    if not path.is_dir():
        raise DataRootError(f"{why}: {path} does not exist (data root from {DATA_DIR_ENV} or ../shared/data)")
    return path


def state_dir() -> Path:
    """humancal's own state folder (created on first use)."""
    configured = os.environ.get(STATE_DIR_ENV)
    path = Path(configured).expanduser() if configured else REPO_ROOT / ".humancal"
    path.mkdir(parents=True, exist_ok=True)
    return path


def anny_cache_dir() -> Path:
    """Cache folder for anny's built model data (``ANNY_CACHE_DIR`` when set)."""
    configured = os.environ.get("ANNY_CACHE_DIR")
    return Path(configured) if configured else state_dir() / "cache" / "anny"
