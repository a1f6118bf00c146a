"""The CLI's persistent Dagster instance, in ``<state dir>/dagster_home`` (telemetry off), shared by every command.

Standard library only at import time (the parser of ``humancal --help`` imports this module).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["dagster_home", "persistent_instance"]


def dagster_home() -> Path:
    """The persistent DAGSTER_HOME of this checkout (created with telemetry disabled)."""
    from humancal.settings import state_dir

    home = state_dir() / "dagster_home"
    home.mkdir(parents=True, exist_ok=True)
    config = home / "dagster.yaml"
    if not config.exists():
        config.write_text("telemetry:\n  enabled: false\n")
    return home


def persistent_instance():
    """The persistent instance; runs left unfinished by a killed ``humancal`` process are marked failed first
    (``pipelines.run_guard``)."""
    os.environ["DAGSTER_HOME"] = str(dagster_home())
    import dagster as dg

    from pipelines.run_guard import fail_dead_runs

    instance = dg.DagsterInstance.get()
    for line in fail_dead_runs(instance):
        print(f"humancal: {line}", file=sys.stderr)
    return instance
