"""The no-op shortcut of ``humancal update`` and ``humancal demo``: nothing changed, so nothing to do.

Deciding that nothing is missing or stale needs the Definitions (which import torch, anny and every asset module:
about 4 s) and a staleness query per asset partition. After an update that found nothing to do, the command
stores what it printed beside a *fingerprint* of everything its answer depends on (``<local dir>/update_stamp.json``;
the local dir is the state dir unless that is on a store: :mod:`humancal.settings`). The next identical command
computes the fingerprint again (file sizes and modification times only: a few milliseconds, no Dagster, no torch)
and, when it is unchanged, prints the stored lines and exits with the stored status. Anything else takes the full
path.

The fingerprint covers:

* the command and its partitions;
* the source and data files of the packages (``humancal``, ``assets``, ``resources``, ``pipelines``,
  ``evaluation``): code versions, shipped weights, the packaged datasets config and the paper's numbers live there;
  the interpreter's version and its site-packages folders (an installed or removed package changes them);
* the settings: ``HUMANCAL_DATA_DIR``, ``HUMANCAL_DATASETS``, ``HUMANCAL_STATE_DIR``, ``HUMANCAL_LOCAL_DIR``,
  ``HUMANCAL_CELERY_BROKER``, the folders at the top of the data root (which sequences can be registered), the
  datasets config files and the user datasets file;
* the Dagster instance's storage files under ``<local dir>/dagster_home`` (any run, materialization, check
  evaluation or partition change writes them) and its ``dagster.yaml``; the shortcut is off when that file
  configures another storage (a database server), whose changes leave no trace here, and when the state dir is
  on a store (which needs such a server anyway);
* every file under ``<state dir>/artifacts`` (a deleted, damaged or added artifact changes it), and the record of
  failed asset partitions.

A killed run changes the instance's files too, so the next command takes the full path, which marks the run
failed (``pipelines.run_guard``).
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import tempfile
from pathlib import Path

__all__ = ["Output", "fingerprint", "replay", "store"]

FILE_NAME = "update_stamp.json"
PACKAGES = ("humancal", "assets", "resources", "pipelines", "evaluation")
SETTINGS = ("HUMANCAL_DATA_DIR", "HUMANCAL_DATASETS", "HUMANCAL_STATE_DIR", "HUMANCAL_LOCAL_DIR",
            "HUMANCAL_CELERY_BROKER")
MAX_ENTRIES = 8
DEFAULT_DAGSTER_YAML = "telemetry:\n  enabled: false\n"


class Output:
    """Lines a command prints (``stream`` ``"out"`` or ``"err"``; ``verbose``: only with ``-v``), recorded so that
    the shortcut can print them again."""

    def __init__(self, verbose: bool, echo: bool = True):
        self.verbose, self.echo = verbose, echo
        self.lines: list[tuple[str, bool, str]] = []

    def __call__(self, text: str, stream: str = "out", verbose: bool = False) -> None:
        self.lines.append((stream, verbose, text))
        if self.echo:
            _emit(stream, verbose, text, self.verbose)


def _emit(stream: str, verbose_only: bool, text: str, verbose: bool) -> None:
    if verbose_only and not verbose:
        return
    print(text, file=sys.stderr if stream == "err" else sys.stdout, flush=True)


def _files(root: Path, skip: tuple[str, ...] = ()) -> list[str]:
    """``relative path:size:mtime_ns`` of every file under ``root`` (folders named in ``skip`` and ``__pycache__``
    left out), sorted."""
    out = []
    for folder, dirs, names in os.walk(root):
        dirs[:] = [d for d in dirs if d != "__pycache__" and d not in skip]
        for name in names:
            path = os.path.join(folder, name)
            try:
                stat = os.stat(path)
            except OSError:
                continue
            out.append(f"{os.path.relpath(path, root)}:{stat.st_size}:{stat.st_mtime_ns}")
    return sorted(out)


def _stat(path: Path) -> str:
    try:
        stat = os.stat(path)
    except OSError:
        return f"{path}:none"
    return f"{path}:{stat.st_size}:{stat.st_mtime_ns}"


def fingerprint(command: str) -> str | None:
    """The fingerprint of ``command`` in the present state (``None``: the shortcut does not apply here)."""
    from humancal.datasets.sequences import default_config_path, user_config_path
    from humancal.settings import REPO_ROOT, data_root, local_dir, state_dir, state_url

    if state_url() is not None:
        return None  # a store: its changes leave no trace in this machine's files
    home = local_dir() / "dagster_home"
    try:
        if (home / "dagster.yaml").read_text() != DEFAULT_DAGSTER_YAML:
            return None  # another storage may be configured: its changes leave no trace in these files
    except OSError:
        return None
    parts = [command, sys.version, sys.executable]
    parts += [_stat(Path(p)) for p in sys.path if p.endswith("site-packages")]
    for package in PACKAGES:
        parts += [f"{package}/{f}" for f in _files(REPO_ROOT / package)]
    parts += [f"{name}={os.environ.get(name, '')}" for name in SETTINGS]
    root = data_root()
    parts.append(f"data root {root}")
    if root is not None:
        parts += sorted(f"{e.name}:{e.is_dir()}" for e in os.scandir(root))
    parts += [_stat(default_config_path()), _stat(user_config_path())]
    parts += [f"home/{f}" for f in _files(home, skip=("storage",))]
    parts += [f"artifacts/{f}" for f in _files(state_dir() / "artifacts")]
    parts += [_stat(state_dir() / "update_failures.json")]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()


def _read(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return {}


def replay(command: str, verbose: bool) -> int | None:
    """Print what ``command`` printed last time and return its exit status, when nothing changed since
    (``None``: something did, or no stamp; take the full path)."""
    from humancal.settings import local_dir

    entry = _read(local_dir() / FILE_NAME).get(command)
    if not entry:
        return None
    now = fingerprint(command)
    if now is None or now != entry.get("fingerprint"):
        return None
    for stream, verbose_only, text in entry["lines"]:
        _emit(stream, verbose_only, text, verbose)
    if verbose:
        print(f"(nothing changed since {entry.get('written', 'the last run')}: its output, from {FILE_NAME})",
              file=sys.stderr)
    return int(entry["status"])


def store(command: str, print_fingerprint: str | None, output: Output, status: int) -> bool:
    """Record ``output`` and ``status`` for ``command``, if the fingerprint taken before the command decided
    anything (``print_fingerprint``) still holds (nothing changed while it ran); says whether."""
    import time

    from humancal.settings import local_dir

    if print_fingerprint is None or fingerprint(command) != print_fingerprint:
        return False
    path = local_dir() / FILE_NAME
    entries = _read(path)
    entries[command] = {"fingerprint": print_fingerprint, "lines": output.lines, "status": status,
                        "written": time.strftime("%Y-%m-%d %H:%M:%S")}
    while len(entries) > MAX_ENTRIES:
        entries.pop(next(iter(entries)))
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{FILE_NAME}.", suffix=".tmp", dir=path.parent)
    except OSError:
        return False  # a read-only state dir: the shortcut is simply not taken next time
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(entries, f)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return True
