"""``humancal worker``: a Celery worker that runs the steps ``humancal update`` sends to the cluster.

A thin wrapper over ``celery worker`` with the project's app (:mod:`pipelines.celery_app`) and settings
(:mod:`pipelines.cluster`): start one per machine (or several on a big one: each runs one step at a time, and a
step's torch uses every core) with the same ``HUMANCAL_*`` environment as the coordinator. It replaces this process
with Celery's, so ``kill`` and Ctrl-C reach Celery.
"""

from __future__ import annotations

import os
import signal
import socket
import sys
from pathlib import Path


def add_parser(sub) -> None:
    p = sub.add_parser("worker", help="run a Celery worker for `humancal update` on a cluster (docs/cluster.md)")
    p.add_argument("--name", default=None, help="the worker's name (default humancal-<pid>@<host>)")
    p.add_argument("--loglevel", default="INFO", choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    p.set_defaults(func=cmd_worker)


def cmd_worker(args) -> int:
    from pipelines.cluster import BROKER_ENV, QUEUE, ClusterSettings
    from pipelines.instance import configure_instance_env

    settings = ClusterSettings.from_env()
    if settings is None:
        raise ValueError(f"humancal worker needs {BROKER_ENV}, the broker humancal update sends its steps to "
                         "(e.g. redis://localhost:6379/0); see docs/cluster.md")
    configure_instance_env()
    repo = Path(__file__).resolve().parents[2]
    name = args.name or f"humancal-{os.getpid()}@{socket.gethostname()}"
    # One step at a time, in the worker's own process (Celery's solo pool): in a child forked by Celery's default
    # prefork pool, torch ran the body fit 10 to 25 times slower here. A big machine runs several workers.
    argv = [sys.executable, "-m", "celery", "-A", "pipelines.celery_app", "worker", "-Q", QUEUE, "--pool", "solo",
            "--hostname", name, "--loglevel", args.loglevel, "--without-mingle", "--without-gossip"]
    print(f"humancal worker {name}: steps from {settings.broker_url} (queue {QUEUE}), one at a time",
          file=sys.stderr, flush=True)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(repo), os.environ.get("PYTHONPATH")])))
    signal.signal(signal.SIGINT, signal.SIG_DFL)  # see cmd_ui: a background start inherits SIGINT ignored
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    os.chdir(repo)
    os.execvpe(argv[0], argv, env)
    return 0  # not reached
