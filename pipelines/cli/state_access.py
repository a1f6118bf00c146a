"""A read-only state dir is one line naming the path and what to do, not a traceback.

The commands that write the state dir (``demo``, ``update``, ``add``, ``remove``, ``train``, ``benchmark``,
``ui``) check it first: the folder, the Dagster instance's folders and database files, the artifacts folder and
the user datasets file must be writable (``os.access``: the permission bits, a read-only file system; no file is
created). The same holds for the local dir when it is another folder (``HUMANCAL_LOCAL_DIR``, or a state dir on a
store: :mod:`humancal.settings`). A state dir on a store is not checked here (a store's permissions are known only
by writing); a write refused there is an error naming the object. A permission error met later anyway (a file made
read-only by hand) is reported the same way by the CLI's ``main``.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["StateNotWritable", "permission_message", "require_writable_state"]

ADVICE = "make it writable (e.g. chmod -R u+w {state}) or set {variable} to a writable folder"


class StateNotWritable(SystemExit):
    """The state dir (or a file in it) cannot be written; the message names the path and what to do."""


def _instance_paths(local: Path) -> list[Path]:
    home = local / "dagster_home"
    return [local, home, home / "dagster.yaml", home / "history", home / "history" / "runs.db",
            home / "history" / "runs", home / "history" / "runs" / "index.db", home / "schedules",
            home / "schedules" / "schedules.db", home / "storage"]


def _checks(state: Path | None, local: Path) -> list[tuple[Path, str, Path, str]]:
    """``(path, "the state dir" or "the local dir", that folder, the variable setting it)`` of each existing path
    to check, in order (``state``: ``None`` for a state dir on a store)."""
    from humancal.settings import LOCAL_DIR_ENV, STATE_DIR_ENV

    same = state is not None and Path(local).resolve() == Path(state).resolve()
    own = LOCAL_DIR_ENV if os.environ.get(LOCAL_DIR_ENV, "").strip() else STATE_DIR_ENV
    local_label = ("the state dir" if same else "the local dir", local, own)
    checks = [(p, *local_label) for p in _instance_paths(local)]
    if state is not None:
        shared = [(p, "the state dir", state, STATE_DIR_ENV)
                  for p in (state, state / "artifacts", state / "datasets.yaml")]
        checks = shared[:1] + checks + shared[1:]
    out, seen = [], set()
    for check in checks:
        if str(check[0]) not in seen and check[0].exists():
            seen.add(str(check[0]))
            out.append(check)
    return out


def require_writable_state():
    """The state dir, checked to be writable (with the local dir).

    Raises:
        StateNotWritable: the state dir or the local dir cannot be created, or one of them or one of the instance's
            files is read-only.
    """
    from humancal.settings import LOCAL_DIR_ENV, STATE_DIR_ENV, local_dir, state_dir, state_url

    try:
        state = state_dir()
    except OSError as err:
        where = os.environ.get(STATE_DIR_ENV) or err.filename
        raise StateNotWritable(f"humancal: cannot create the state dir {where}: {err.strerror}; set "
                               f"{STATE_DIR_ENV} to a writable folder") from None
    try:
        local = local_dir()
    except OSError as err:
        variable = LOCAL_DIR_ENV if os.environ.get(LOCAL_DIR_ENV, "").strip() else STATE_DIR_ENV
        raise StateNotWritable(f"humancal: cannot create the local dir {err.filename}: {err.strerror}; set "
                               f"{variable} to a writable folder") from None
    for path, what, folder, variable in _checks(state if state_url() is None else None, local):
        mode = os.W_OK | (os.X_OK if path.is_dir() else 0)
        if not os.access(path, mode):
            raise StateNotWritable(f"humancal: {what} is read-only: cannot write {path}; "
                                   + ADVICE.format(state=folder, variable=variable))
    return state


def permission_message(err: PermissionError) -> str:
    """One line for a permission error met while writing: the path, and what to do."""
    from humancal.settings import LOCAL_DIR_ENV, REPO_ROOT, STATE_DIR_ENV, state_url

    path = err.filename or "a file"
    folders = []
    if os.environ.get(LOCAL_DIR_ENV, "").strip():
        folders.append((Path(os.environ[LOCAL_DIR_ENV]).expanduser(), LOCAL_DIR_ENV))
    if state_url() is None:
        folders.append((Path(os.environ.get(STATE_DIR_ENV) or REPO_ROOT / ".humancal").expanduser(), STATE_DIR_ENV))
    elif not folders:
        folders.append((REPO_ROOT / ".humancal", LOCAL_DIR_ENV))
    for folder, variable in folders:
        if isinstance(err.filename, str) and Path(err.filename).expanduser().resolve().is_relative_to(folder.resolve()):
            return f"humancal: cannot write {path}: {err.strerror}; " + ADVICE.format(state=folder, variable=variable)
    return f"humancal: cannot write {path}: {err.strerror}; make it writable or choose another path"
