"""The CLI's persistent Dagster instance, in ``<state dir>/dagster_home`` (telemetry off), shared by every command.

Its history (runs, materializations, partitions) is kept in SQLite files in that folder, or on Postgres when
``HUMANCAL_POSTGRES_URL`` is set (a cluster: :mod:`pipelines.cluster`). The ``dagster.yaml`` written there says
which; a ``dagster.yaml`` edited by hand (one this module did not write) is left as it is.

Standard library only at import time (the parser of ``humancal --help`` imports this module).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["configure_instance_env", "dagster_home", "instance_config", "persistent_instance"]

POSTGRES_ENV = "HUMANCAL_POSTGRES_URL"
_LOCAL = "telemetry:\n  enabled: false\n"
_POSTGRES = _LOCAL + f"storage:\n  postgres:\n    postgres_url:\n      env: {POSTGRES_ENV}\n"


def instance_config() -> str:
    """The ``dagster.yaml`` humancal writes: SQLite in the folder, or Postgres when ``HUMANCAL_POSTGRES_URL`` is set
    (the URL itself stays in the environment, not in the file)."""
    return _POSTGRES if os.environ.get(POSTGRES_ENV, "").strip() else _LOCAL


def dagster_home() -> Path:
    """The persistent DAGSTER_HOME of this checkout, its ``dagster.yaml`` written by :func:`instance_config`."""
    from humancal.settings import state_dir

    home = state_dir() / "dagster_home"
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
