"""Where humancal reads external data and keeps its own state.

Settings are environment variables, so that a notebook, the CLI, Dagster and every worker of a cluster agree:

``HUMANCAL_DATA_DIR``
    Root of external datasets (CMU mocap, Shelf, Human3.6M cameras; see the README's "Data" section).
    Default: ``../shared/data`` beside the repository checkout, when that folder exists.
``HUMANCAL_STATE_DIR``
    humancal's own state, shared by every machine that works on the same captures: a local folder (default:
    ``.humancal`` inside the repository checkout, ignored by git) or an fsspec URL (``s3://bucket/prefix``,
    ``gs://...``, ``memory://...``, with the store's fsspec package installed; :func:`state_dir`).
``HUMANCAL_LOCAL_DIR``
    What each machine keeps for itself (:func:`local_dir`). Default: the state dir when that is a local folder
    (so nothing moves), else ``.humancal`` inside the checkout.

What goes where:

* **The state dir** (shared): the artifacts (``artifacts/``: Parquet tables, checkpoints, the trained weights of
  ``lifter_trained`` and the prior), the user datasets file (``datasets.yaml``: a worker on any machine must know
  every registered capture) and the record of failed asset partitions (``update_failures.json``: ``humancal
  update`` may be run from any machine, and must not retry there what failed elsewhere).
* **The local dir** (per machine): the body model's cache (``cache/anny``: about 790 MB that anny builds from its
  own files, the same on every machine; built once per machine, then read by every step run there), the Dagster
  home (``dagster_home/``: its ``dagster.yaml``, and the SQLite history when the instance is not on Postgres), the
  no-op stamp of ``humancal update`` (``update_stamp.json``: it fingerprints this machine's files) and the capture
  inbox (``inbox/``: a sensor watches a folder of the machine it runs on).

A state dir on a store needs the Dagster instance on Postgres (``HUMANCAL_POSTGRES_URL``,
:mod:`pipelines.instance`): artifacts that every machine shares need one history that every machine shares,
and SQLite files cannot live on an object store.

How to reach the store (endpoint, credentials, options) is not a humancal setting: each fsspec filesystem reads
its own configuration, the same in every process. For S3 and S3-compatible servers (MinIO, Ceph): the usual
``AWS_ACCESS_KEY_ID`` / ``AWS_SECRET_ACCESS_KEY`` (or a profile), and fsspec's ``FSSPEC_S3_ENDPOINT_URL`` (any
``FSSPEC_<PROTOCOL>_<OPTION>``, or ``FSSPEC_<PROTOCOL>`` holding a JSON object of options).

Writes of shared files are atomic: :func:`humancal.storage.write_atomic`.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from upath import UPath

DATA_DIR_ENV = "HUMANCAL_DATA_DIR"
STATE_DIR_ENV = "HUMANCAL_STATE_DIR"
LOCAL_DIR_ENV = "HUMANCAL_LOCAL_DIR"
LOCAL_PROTOCOLS = ("", "file", "local")
"""fsspec protocols of this machine's file system (a ``file://`` URL is a local folder)."""

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


def state_url() -> str | None:
    """The state dir's URL when ``HUMANCAL_STATE_DIR`` names a store (``s3://bucket/prefix``), else ``None`` (a
    local folder, ``file://`` URLs included). Reads the variable only: no folder is created, no store is reached."""
    configured = os.environ.get(STATE_DIR_ENV, "").strip()
    protocol, sep, _ = configured.partition("://")
    return configured.rstrip("/") if sep and protocol.lower() not in LOCAL_PROTOCOLS else None


def _local_state_path() -> Path:
    configured = os.environ.get(STATE_DIR_ENV, "").strip()
    if not configured:
        return REPO_ROOT / ".humancal"
    protocol, sep, rest = configured.partition("://")
    return Path(rest if sep else configured).expanduser()


def state_dir() -> UPath:
    """humancal's shared state (module docstring): a local folder, created on first use, or a place on a store.

    A local folder comes as a ``pathlib.Path`` (``upath``'s local ``UPath`` is one); a store's place is not created
    (object stores have no folders: a key exists once an object is written under it).

    Raises:
        OSError: a local state dir cannot be created.
    """
    from upath import UPath

    url = state_url()
    if url is not None:
        return UPath(url)
    path = _local_state_path()
    path.mkdir(parents=True, exist_ok=True)
    return UPath(path)


def local_dir() -> Path:
    """This machine's own folder (module docstring), created on first use: ``HUMANCAL_LOCAL_DIR``, else the state
    dir when that is a local folder, else ``.humancal`` in the checkout.

    Raises:
        ValueError: ``HUMANCAL_LOCAL_DIR`` is a URL (it must be a folder of this machine).
        OSError: the folder cannot be created.
    """
    configured = os.environ.get(LOCAL_DIR_ENV, "").strip()
    if "://" in configured:
        raise ValueError(f"{LOCAL_DIR_ENV}={configured!r}: expected a folder of this machine, not a URL (the shared "
                         f"state goes to {STATE_DIR_ENV})")
    if configured:
        path = Path(configured).expanduser()
    elif state_url() is None:
        path = _local_state_path()
    else:
        path = REPO_ROOT / ".humancal"
    path.mkdir(parents=True, exist_ok=True)
    return path


def anny_cache_dir() -> Path:
    """Cache folder for anny's built model data: ``ANNY_CACHE_DIR`` when set, else ``<local dir>/cache/anny``."""
    configured = os.environ.get("ANNY_CACHE_DIR")
    return Path(configured) if configured else local_dir() / "cache" / "anny"
