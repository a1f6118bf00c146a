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


THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
"""How many threads torch's OpenMP and the BLAS libraries start with: set by ``--threads``. Two workers of two threads
each on two cores ran the body fit of a small capture in 195 s, one thread each in at most 16 s: threads that wait for
each other."""


def add_parser(sub) -> None:
    p = sub.add_parser("worker", help="run a Celery worker for `humancal update` on a cluster (docs/cluster.md)")
    p.add_argument("--threads", type=int, default=None,
                   help="threads of torch and the numerical libraries in this worker (default: their own setting, "
                        "every core); several workers on one machine: give each its share of the cores")
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
    if args.threads is not None and args.threads < 1:
        raise ValueError(f"--threads {args.threads}: expected a whole number >= 1")
    configure_instance_env()
    repo = Path(__file__).resolve().parents[2]
    name = args.name or f"humancal-{os.getpid()}@{socket.gethostname()}"
    # One step at a time, in the worker's own process (Celery's solo pool): a step's torch uses the worker's threads,
    # and a killed worker is one process. A big machine runs several workers, each with its share of the cores.
    argv = [sys.executable, "-m", "celery", "-A", "pipelines.celery_app", "worker", "-Q", QUEUE, "--pool", "solo",
            "--hostname", name, "--loglevel", args.loglevel, "--without-mingle", "--without-gossip"]
    threads = f"{args.threads} threads" if args.threads else "threads: every core"
    print(f"humancal worker {name}: steps from {settings.broker_url} (queue {QUEUE}), one at a time, {threads}",
          file=sys.stderr, flush=True)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(repo), os.environ.get("PYTHONPATH")])))
    if args.threads is not None:  # read by torch (OpenMP), OpenBLAS and MKL when they start
        env.update({name: str(args.threads) for name in THREAD_VARIABLES})
    signal.signal(signal.SIGINT, signal.SIG_DFL)  # see cmd_ui: a background start inherits SIGINT ignored
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    os.chdir(repo)
    os.execvpe(argv[0], argv, env)
    return 0  # not reached
