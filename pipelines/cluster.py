"""Steps on Celery workers: the settings of a humancal cluster, and the runs ``humancal update`` sends there.

A cluster is configured by environment variables, so that ``humancal update`` (the coordinator) and every
``humancal worker`` agree without a file to copy around:

``HUMANCAL_CELERY_BROKER``
    The Celery broker, e.g. ``redis://host:6379/0``. When set, ``humancal update`` sends every step to the
    workers (``dagster-celery``'s executor) and runs the partitions of a round at the same time; when unset,
    nothing changes: steps run in the ``humancal`` process.
``HUMANCAL_CELERY_BACKEND``
    Where workers put their results (default: the broker's URL).
``HUMANCAL_CELERY_VISIBILITY_TIMEOUT_S``
    Seconds after which a step taken by a worker that died (``kill -9``, a lost machine) is given to another
    worker (default 3600). A step running longer than this is given out a second time while it runs, so keep it
    above the longest step (the body fit of the longest capture).
``HUMANCAL_POSTGRES_URL``
    The Dagster instance (runs, materializations, partitions) on Postgres, e.g.
    ``postgresql://user:password@host:5432/humancal`` (:mod:`pipelines.instance`). Workers on other machines need
    it; workers on the coordinator's machine can share its SQLite instance.

Every worker must see the same state dir (``HUMANCAL_STATE_DIR``: the artifacts with the trained weights, the user
datasets file; a folder every machine mounts, or a store's URL such as ``s3://bucket/prefix``) and the same checkout
of humancal. Each machine keeps its own body model's cache and Dagster home in its local dir
(``HUMANCAL_LOCAL_DIR``; :mod:`humancal.settings`). See ``docs/cluster.md``.

Each run a worker executes is rebuilt there from :func:`selection_job` (a reconstructable job: the module, the
function and its arguments travel with the step), from the worker's own ``pipelines.definitions``.
"""

from __future__ import annotations

import logging.config
import os
import threading
import warnings
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass

__all__ = ["BROKER_ENV", "ClusterSettings", "RunRequest", "answering_workers", "run_on_cluster", "selection_job"]

BROKER_ENV = "HUMANCAL_CELERY_BROKER"
BACKEND_ENV = "HUMANCAL_CELERY_BACKEND"
VISIBILITY_ENV = "HUMANCAL_CELERY_VISIBILITY_TIMEOUT_S"
QUEUE = "dagster"
"""The Celery queue of dagster-celery's steps (its apps route every task there)."""
SELECTION_JOB_NAME = "humancal_cluster_run"


@dataclass(frozen=True)
class ClusterSettings:
    """Where the coordinator and the workers meet (read from the environment: :meth:`from_env`)."""

    broker_url: str
    backend_url: str
    visibility_timeout_s: int = 3600

    @classmethod
    def from_env(cls, environ: dict[str, str] | None = None) -> ClusterSettings | None:
        """The settings of ``HUMANCAL_CELERY_*``; ``None`` when no broker is configured (steps run locally).

        Raises:
            ValueError: a malformed variable, named with the form it expects.
        """
        env = os.environ if environ is None else environ
        broker = env.get(BROKER_ENV, "").strip()
        if not broker:
            return None
        if "://" not in broker:
            raise ValueError(f"{BROKER_ENV}={broker!r}: expected a broker URL such as redis://localhost:6379/0")
        timeout = env.get(VISIBILITY_ENV, "3600").strip()
        if not timeout.isdigit() or int(timeout) < 1:
            raise ValueError(f"{VISIBILITY_ENV}={timeout!r}: expected a whole number of seconds >= 1")
        return cls(broker, env.get(BACKEND_ENV, "").strip() or broker, int(timeout))

    def celery_config(self) -> dict:
        """Settings of the Celery app, shared by the executor (coordinator) and the workers.

        A step is acknowledged when it ends, not when a worker takes it (``task_acks_late``), and a worker that
        dies puts it back (``task_reject_on_worker_lost``; a worker killed whole: the broker gives it out again
        after the visibility timeout). A worker takes one step at a time (``worker_prefetch_multiplier``), so that
        a long body fit does not hold back steps another worker could run.
        """
        return {
            "task_acks_late": True,
            "task_reject_on_worker_lost": True,
            "worker_prefetch_multiplier": 1,
            "broker_transport_options": {"visibility_timeout": self.visibility_timeout_s},
            "result_backend_transport_options": {"visibility_timeout": self.visibility_timeout_s},
            "broker_connection_retry_on_startup": True,
        }

    def executor_config(self) -> dict:
        """The ``execution`` section of a run's config: dagster-celery's executor with these settings."""
        return {"config": {"broker": self.broker_url, "backend": self.backend_url,
                           "config_source": self.celery_config()}}

    def app_args(self) -> dict:
        """The arguments of ``dagster_celery.make_app.make_app`` for the workers' app."""
        return {"broker": self.broker_url, "backend": self.backend_url, "include": [],
                "config_source": self.celery_config()}


def answering_workers(settings: ClusterSettings, timeout_s: float = 3.0) -> list[str]:
    """The names of the workers that answer a ping within ``timeout_s`` (a worker busy with a step does not answer).

    Raises:
        ValueError: the broker cannot be reached; the message names the URL and the variable.
    """
    from dagster_celery.make_app import make_app

    app = make_app(settings.app_args())
    try:
        with app.connection_for_write() as connection:
            connection.ensure_connection(max_retries=1, timeout=timeout_s)
    except Exception as err:  # kombu raises the transport's own errors
        why = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise ValueError(f"{BROKER_ENV}={settings.broker_url}: the broker cannot be reached ({why}); start it, or "
                         f"unset {BROKER_ENV} to run the steps here (docs/cluster.md)") from None
    return sorted(name for answer in app.control.ping(timeout=timeout_s) for name in answer)


def selection_job(asset_keys: Sequence[str]):
    """The job materializing ``asset_keys`` (user strings) of the humancal graph, steps on Celery workers.

    The reconstructor of every cluster run: the coordinator and each worker call it with the same keys. It
    mirrors ``dg.materialize``: every asset and check of :data:`pipelines.definitions.defs`, the selection, and
    the resources.
    """
    import dagster as dg
    from dagster_celery import celery_executor

    from pipelines.definitions import defs

    job = dg.define_asset_job(SELECTION_JOB_NAME, selection=dg.AssetSelection.assets(*asset_keys),
                              executor_def=celery_executor)
    return dg.Definitions(assets=[*defs.assets, *(defs.asset_checks or [])], resources=defs.resources,
                          jobs=[job]).resolve_job_def(SELECTION_JOB_NAME)


@dataclass(frozen=True)
class RunRequest:
    """One run of an update round: asset keys of one partition (``None``: unpartitioned) and its run config."""

    partition: str | None
    asset_keys: tuple[str, ...]
    run_config: dict


def run_on_cluster(
    requests: Sequence[RunRequest],
    instance,
    settings: ClusterSettings,
    tags: dict[str, str],
    on_done: Callable[[RunRequest, object], None] | None = None,
) -> list:
    """Execute ``requests`` at the same time, every step on the workers; returns their results in order.

    Each run is orchestrated by a thread of this process (it only submits steps and waits for them), so the
    partitions of a round are spread over every worker. A run that fails does not stop the others.

    Args:
        requests: the runs.
        instance: a persistent Dagster instance the workers can open (Postgres, or SQLite on this machine).
        settings: the cluster.
        tags: tags of every run (the run guard's, :func:`pipelines.run_guard.run_tags`).
        on_done: called, from the run's thread, with each request and its result as it ends.

    Returns:
        ``dagster.JobExecutionResult`` per request (``raise_on_error=False``: failures are in the results).
    """
    import dagster as dg

    if instance.is_ephemeral:
        raise ValueError("a cluster run needs a persistent Dagster instance that the workers can open")
    lock = threading.Lock()

    def execute(request: RunRequest):
        job = dg.build_reconstructable_job("pipelines.cluster", "selection_job",
                                           reconstructable_args=(list(request.asset_keys),))
        config = {**request.run_config, "execution": settings.executor_config()}
        run_tags = dict(tags)
        if request.partition is not None:
            run_tags["dagster/partition"] = request.partition
        result = dg.execute_job(job, instance, run_config=config, tags=run_tags, raise_on_error=False)
        if on_done is not None:
            with lock:
                on_done(request, result)
        return result

    if not requests:
        return []
    # dagster-celery registers its step task again for every step it submits, and Celery warns each time.
    warnings.filterwarnings("ignore", message=r"Task name '.*' is already registered")
    with _no_empty_logging_reconfiguration(), \
            ThreadPoolExecutor(max_workers=len(requests), thread_name_prefix="humancal-run") as pool:
        return list(pool.map(execute, requests))


@contextmanager
def _no_empty_logging_reconfiguration():
    """Skip the ``logging.config.dictConfig`` calls that configure no handler, while runs share this process.

    Dagster calls ``dictConfig`` as each run starts, to collect the Python log handlers of the instance's
    ``python_logs`` settings, also when there are none. ``dictConfig`` holds the logging module's lock while it
    closes every handler, each under its own lock; a run of another thread that is writing an event holds its
    handler's lock and then asks for the module's lock (SQLAlchemy's logger): the two threads wait for each other
    for ever. Seen here with two runs. A configuration without handlers changes nothing Dagster reads (its dummy
    logger has no handler either way), so it is skipped; any other goes through.
    """
    original = logging.config.dictConfig

    def dict_config(config):
        if not config.get("handlers") and set(config) <= {"version", "disable_existing_loggers", "loggers"} \
                and all(not spec.get("handlers") for spec in config.get("loggers", {}).values()):
            return None
        return original(config)

    logging.config.dictConfig = dict_config
    try:
        yield
    finally:
        logging.config.dictConfig = original
