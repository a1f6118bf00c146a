"""humancal on a cluster (pipelines/cluster.py, `humancal worker`, scripts/local_cluster.py): settings, the worker
command, the job every worker rebuilds, and (slow) a real cluster of Redis, Postgres and two Celery workers."""

from __future__ import annotations

import json
import logging.config
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from pipelines.cli import main
from pipelines.cluster import ClusterSettings, _no_empty_logging_reconfiguration, answering_workers, selection_job
from pipelines.instance import configure_instance_env, instance_config

REPO = Path(__file__).resolve().parents[2]


def test_no_broker_means_no_cluster_and_a_broker_configures_both_sides():
    assert ClusterSettings.from_env({}) is None
    settings = ClusterSettings.from_env({"HUMANCAL_CELERY_BROKER": "redis://h:6379/0",
                                         "HUMANCAL_CELERY_VISIBILITY_TIMEOUT_S": "120"})
    assert settings.backend_url == "redis://h:6379/0"  # the broker's, by default
    execution = settings.executor_config()["config"]
    assert execution["broker"] == settings.app_args()["broker"] == "redis://h:6379/0"
    # the executor and the workers share one Celery configuration: a step is acknowledged when it ends
    assert execution["config_source"] == settings.app_args()["config_source"]
    assert execution["config_source"]["task_acks_late"] and execution["config_source"]["task_reject_on_worker_lost"]
    assert execution["config_source"]["broker_transport_options"]["visibility_timeout"] == 120


@pytest.mark.parametrize(("env", "words"), [
    ({"HUMANCAL_CELERY_BROKER": "localhost:6379"}, "HUMANCAL_CELERY_BROKER"),
    ({"HUMANCAL_CELERY_BROKER": "redis://h/0", "HUMANCAL_CELERY_VISIBILITY_TIMEOUT_S": "1h"},
     "HUMANCAL_CELERY_VISIBILITY_TIMEOUT_S"),
])
def test_a_malformed_setting_is_named(env, words):
    with pytest.raises(ValueError, match=words):
        ClusterSettings.from_env(env)


def test_an_unreachable_broker_is_an_error_naming_it(monkeypatch, tmp_path, capsys):
    import socket

    with socket.socket() as s:  # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    monkeypatch.setenv("HUMANCAL_CELERY_BROKER", f"redis://127.0.0.1:{port}/0")
    with pytest.raises(ValueError, match=f"HUMANCAL_CELERY_BROKER=redis://127.0.0.1:{port}/0: the broker cannot be"):
        answering_workers(ClusterSettings.from_env())


def test_worker_without_a_broker_says_which_variable(monkeypatch, tmp_path, capsys):
    monkeypatch.delenv("HUMANCAL_CELERY_BROKER", raising=False)
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path))
    assert main(["worker"]) == 2
    assert "HUMANCAL_CELERY_BROKER" in capsys.readouterr().err


def test_worker_runs_celery_with_the_projects_app(monkeypatch, tmp_path):
    monkeypatch.setenv("HUMANCAL_CELERY_BROKER", "redis://127.0.0.1:1/0")
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path))
    monkeypatch.setenv("DAGSTER_HOME", str(tmp_path / "elsewhere"))  # restored after the test (the command sets it)
    seen = {}

    def exec_instead(path, argv, env):
        seen.update(argv=argv, env=env)

    monkeypatch.setattr("os.execvpe", exec_instead)
    monkeypatch.setattr("os.chdir", lambda path: None)
    monkeypatch.setattr("signal.signal", lambda *a: None)
    assert main(["worker", "--name", "a@b", "--threads", "3"]) == 0
    argv = seen["argv"]
    assert argv[1:5] == ["-m", "celery", "-A", "pipelines.celery_app"] and "worker" in argv
    assert argv[argv.index("-Q") + 1] == "dagster" and argv[argv.index("--hostname") + 1] == "a@b"
    assert argv[argv.index("--pool") + 1] == "solo"  # one step at a time, in the worker's own process
    assert seen["env"]["OMP_NUM_THREADS"] == seen["env"]["OPENBLAS_NUM_THREADS"] == "3"
    assert seen["env"]["DAGSTER_HOME"] == str(tmp_path / "dagster_home")


def test_the_instance_moves_to_postgres_when_configured(monkeypatch, tmp_path):
    monkeypatch.delenv("HUMANCAL_POSTGRES_URL", raising=False)
    assert "postgres" not in instance_config()
    monkeypatch.setenv("HUMANCAL_POSTGRES_URL", "postgresql://u@h:5432/db")
    config = instance_config()
    assert "env: HUMANCAL_POSTGRES_URL" in config and "postgresql://" not in config  # the URL stays in the env
    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(tmp_path))
    monkeypatch.setenv("DAGSTER_HOME", str(tmp_path / "elsewhere"))  # restored after the test (the function sets it)
    home = configure_instance_env()
    assert (home / "dagster.yaml").read_text() == config
    assert os.environ["HUMANCAL_POSTGRES_URL"] == "postgresql+psycopg2://u@h:5432/db"  # dagster-postgres's driver


def test_every_worker_rebuilds_the_selected_assets_with_the_celery_executor():
    job = selection_job(["extrinsics", "intrinsics"])
    assert job.executor_def.name == "celery"
    assert {node.name for node in job.graph.nodes} == {"extrinsics", "intrinsics"}


def test_an_empty_logging_configuration_is_skipped_while_runs_share_the_process():
    handler = logging.StreamHandler()
    logger = logging.getLogger("humancal_test_cluster")
    logger.addHandler(handler)
    try:
        with _no_empty_logging_reconfiguration():
            # what Dagster passes as each run starts when the instance configures no Python log handler
            logging.config.dictConfig({"version": 1, "disable_existing_loggers": False,
                                       "loggers": {"dagster_dummy_logger": {"handlers": []}}})
            assert handler.stream is not None and logger.handlers == [handler]  # nothing was closed
            logging.config.dictConfig({"version": 1, "disable_existing_loggers": False,
                                       "handlers": {"h": {"class": "logging.NullHandler"}},
                                       "loggers": {"humancal_test_cluster_other": {"handlers": ["h"]}}})
            other = logging.getLogger("humancal_test_cluster_other").handlers
            assert len(other) == 1 and isinstance(other[0], logging.NullHandler)  # a real configuration applies
        assert logging.config.dictConfig.__module__ == "logging.config"  # restored
    finally:
        logger.removeHandler(handler)
        logging.getLogger("humancal_test_cluster_other").handlers.clear()


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("redis-server") is None or not list(Path("/usr/lib/postgresql").glob("*/bin/initdb")),
                    reason="needs Debian's redis-server and postgresql (apt-get install redis-server postgresql)")
def test_twelve_captures_on_two_workers_survive_a_killed_worker(tmp_path):
    """Redis, Postgres and two `humancal worker`s; 12 synthetic captures; one worker killed (kill -9) in the middle of
    a step. Every partition ends materialized, and `humancal update` then has nothing to do."""
    summary_file = tmp_path / "summary.json"
    proc = subprocess.run([sys.executable, "scripts/local_cluster.py", "--workers", "2", "--partitions", "12",
                           "--kill-after", "30", "--json", str(summary_file)],
                          cwd=REPO, capture_output=True, text=True, timeout=1500)
    assert summary_file.exists(), proc.stdout[-3000:] + proc.stderr[-3000:]
    summary = json.loads(summary_file.read_text())
    first, second = summary["first_update"], summary["second_update"]
    assert summary["postgres"] and summary["killed"] == ["w1"], proc.stdout[-3000:]
    assert first["status"] == 0, "\n".join(first["lines"][-30:])
    assert not [line for line in first["lines"] if "FAILED" in line or line.startswith("ERROR")]
    assert second["status"] == 0 and second["materialized"] == 0, "\n".join(second["lines"])
    assert proc.returncode == 0
