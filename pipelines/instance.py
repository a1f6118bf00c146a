"""The CLI's persistent Dagster instance, in ``<local dir>/dagster_home`` (telemetry off), shared by every command.

The local dir is the state dir unless that is on a store (:mod:`humancal.settings`). The history (runs,
materializations, partitions) is kept in SQLite files in that folder, or on Postgres when ``HUMANCAL_POSTGRES_URL``
is set (a cluster: :mod:`pipelines.cluster`). The ``dagster.yaml`` written there says which; a ``dagster.yaml``
edited by hand (one this module did not write) is left as it is. A state dir on a store needs Postgres
(:func:`dagster_home` says so): the history of shared artifacts must be shared too.

Standard library only at import time (the parser of ``humancal --help`` imports this module).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["StoreWithoutPostgres", "configure_instance_env", "dagster_home", "instance_config", "persistent_instance"]

POSTGRES_ENV = "HUMANCAL_POSTGRES_URL"
_LOCAL = "telemetry:\n  enabled: false\n"
_POSTGRES = _LOCAL + f"storage:\n  postgres:\n    postgres_url:\n      env: {POSTGRES_ENV}\n"


def instance_config() -> str:
    """The ``dagster.yaml`` humancal writes: SQLite in the folder, or Postgres when ``HUMANCAL_POSTGRES_URL`` is set
    (the URL itself stays in the environment, not in the file)."""
    return _POSTGRES if os.environ.get(POSTGRES_ENV, "").strip() else _LOCAL


class StoreWithoutPostgres(ValueError):
    """The state dir is on a store and the instance is not on Postgres."""


def dagster_home() -> Path:
    """The persistent DAGSTER_HOME of this machine, ``<local dir>/dagster_home``, its ``dagster.yaml`` written by
    :func:`instance_config`.

    Raises:
        StoreWithoutPostgres: ``HUMANCAL_STATE_DIR`` is a store's URL and ``HUMANCAL_POSTGRES_URL`` is unset.
    """
    from humancal.settings import STATE_DIR_ENV, local_dir, state_url

    url = state_url()
    if url is not None and not os.environ.get(POSTGRES_ENV, "").strip():
        raise StoreWithoutPostgres(
            f"{STATE_DIR_ENV}={url} is on a store, so the Dagster instance must be shared too: set {POSTGRES_ENV}="
            "postgresql://user:password@host:5432/database (a SQLite instance is one machine's files and cannot "
            "live on a store; docs/cluster.md)")
    home = local_dir() / "dagster_home"
    home.mkdir(parents=True, exist_ok=True)
    config = home / "dagster.yaml"
    wanted = instance_config()
    current = config.read_text() if config.exists() else None
    if current != wanted and current in (None, _LOCAL, _POSTGRES):
        config.write_text(wanted)
    return home


def configure_instance_env() -> Path:
    """Point ``DAGSTER_HOME`` at :func:`dagster_home` (for this process and the ones it starts); returns it.

    A ``postgresql://`` (or ``postgres://``) URL in ``HUMANCAL_POSTGRES_URL`` is given psycopg2's driver name:
    dagster-postgres speaks psycopg2, and SQLAlchemy 2.1 would open a bare ``postgresql://`` with psycopg 3.
    """
    url = os.environ.get(POSTGRES_ENV, "").strip()
    for bare in ("postgresql://", "postgres://"):
        if url.startswith(bare):
            os.environ[POSTGRES_ENV] = "postgresql+psycopg2://" + url[len(bare):]
    home = dagster_home()
    os.environ["DAGSTER_HOME"] = str(home)
    return home


def persistent_instance():
    """The persistent instance; runs left unfinished by a killed ``humancal`` process are marked failed first
    (``pipelines.run_guard``)."""
    configure_instance_env()
    import dagster as dg

    from pipelines.run_guard import fail_dead_runs

    instance = dg.DagsterInstance.get()
    for line in fail_dead_runs(instance):
        print(f"humancal: {line}", file=sys.stderr)
    return instance
