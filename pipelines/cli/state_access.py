"""A read-only state dir is one line naming the path and what to do, not a traceback.

The commands that write the state dir (``demo``, ``update``, ``add``, ``remove``, ``train``, ``benchmark``,
``ui``) check it first: the folder, the Dagster instance's folders and database files, the artifacts folder and
the user datasets file must be writable (``os.access``: the permission bits, a read-only file system; no file is
created). A permission error met later anyway (a file made read-only by hand) is reported the same way by the
CLI's ``main``.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["StateNotWritable", "permission_message", "require_writable_state"]

ADVICE = "make it writable (e.g. chmod -R u+w {state}) or set HUMANCAL_STATE_DIR to a writable folder"


class StateNotWritable(SystemExit):
    """The state dir (or a file in it) cannot be written; the message names the path and what to do."""


def _state_paths(state: Path) -> list[Path]:
    home = state / "dagster_home"
    paths = [state, home, home / "dagster.yaml", home / "history", home / "history" / "runs.db",
             home / "history" / "runs", home / "history" / "runs" / "index.db", home / "schedules",
             home / "schedules" / "schedules.db", home / "storage", state / "artifacts", state / "datasets.yaml"]
    return [p for p in paths if p.exists()]


def require_writable_state() -> Path:
    """The state dir, checked to be writable.

    Raises:
        StateNotWritable: the state dir cannot be created, or it or one of the instance's files is read-only.
    """
    from humancal.settings import STATE_DIR_ENV, state_dir

    try:
        state = state_dir()
    except OSError as err:
        where = os.environ.get(STATE_DIR_ENV) or err.filename
        raise StateNotWritable(f"humancal: cannot create the state dir {where}: {err.strerror}; set "
                               "HUMANCAL_STATE_DIR to a writable folder") from None
    for path in _state_paths(state):
        mode = os.W_OK | (os.X_OK if path.is_dir() else 0)
        if not os.access(path, mode):
            raise StateNotWritable(f"humancal: the state dir is read-only: cannot write {path}; "
                                   + ADVICE.format(state=state))
    return state


def permission_message(err: PermissionError) -> str:
    """One line for a permission error met while writing: the path, and what to do."""
    from humancal.settings import STATE_DIR_ENV, REPO_ROOT

    path = err.filename or "a file"
    state = Path(os.environ.get(STATE_DIR_ENV) or REPO_ROOT / ".humancal").expanduser()
    if isinstance(err.filename, str) and Path(err.filename).expanduser().resolve().is_relative_to(state.resolve()):
        return f"humancal: cannot write {path}: {err.strerror}; " + ADVICE.format(state=state)
    return f"humancal: cannot write {path}: {err.strerror}; make it writable or choose another path"
