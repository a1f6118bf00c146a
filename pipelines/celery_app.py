"""The Celery app of ``humancal worker`` (``celery -A pipelines.celery_app worker``).

dagster-celery's step task on the broker and backend of :class:`pipelines.cluster.ClusterSettings`, with the same
Celery settings as the executor that sends the steps.
"""

from __future__ import annotations

from dagster_celery.make_app import make_app
from dagster_celery.tasks import create_task

from pipelines.cluster import BROKER_ENV, ClusterSettings

_settings = ClusterSettings.from_env()
if _settings is None:
    raise RuntimeError(f"a humancal worker needs {BROKER_ENV} (e.g. redis://localhost:6379/0); see docs/cluster.md")

app = make_app(_settings.app_args())
execute_plan = create_task(app)
