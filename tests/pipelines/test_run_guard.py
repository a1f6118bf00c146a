"""A run whose ``humancal`` process was killed with SIGKILL in the middle of a materialization stays STARTED in the
instance; the next command that opens the instance marks it failed. A run whose process lives is left alone."""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import dagster as dg

from pipelines.run_guard import PID_TAG, START_TAG, fail_dead_runs, process_alive, run_tags

REPO = Path(__file__).resolve().parents[2]

SLOW_UPDATE = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    import dagster as dg
    from pipelines.update import update

    marker = Path(sys.argv[1])

    @dg.asset
    def slow() -> None:
        marker.write_text("started")
        time.sleep(120)

    update(dg.Definitions(assets=[slow]), dg.DagsterInstance.get())
""")


def _statuses(instance) -> list[dg.DagsterRunStatus]:
    return [record.dagster_run.status for record in instance.get_run_records()]


def test_a_run_killed_in_the_middle_is_marked_failed_by_the_next_command(tmp_path, monkeypatch, capsys):
    state = tmp_path / "state"
    home = state / "dagster_home"
    home.mkdir(parents=True)
    (home / "dagster.yaml").write_text("telemetry:\n  enabled: false\n")
    env = dict(os.environ, DAGSTER_HOME=str(home), HUMANCAL_STATE_DIR=str(state))
    marker = tmp_path / "started"
    proc = subprocess.Popen([sys.executable, "-c", SLOW_UPDATE, str(marker)], cwd=REPO, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.time() + 120
    while not marker.exists():
        assert proc.poll() is None and time.time() < deadline, proc.stderr.read().decode()[-2000:]
        time.sleep(0.1)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)

    monkeypatch.setenv("HUMANCAL_STATE_DIR", str(state))
    monkeypatch.setenv("DAGSTER_HOME", str(home))  # restored after the test (the CLI sets it)
    instance = dg.DagsterInstance.get()
    assert _statuses(instance) == [dg.DagsterRunStatus.STARTED]  # what the UI shows as in progress, for ever
    run = instance.get_run_records()[0].dagster_run
    assert run.tags[PID_TAG] == str(proc.pid)

    import pipelines.cli as cli

    cli._instance()  # any command that opens the instance
    assert f"marked run {run.run_id[:8]} failed: its process {proc.pid} ended" in capsys.readouterr().err
    assert _statuses(dg.DagsterInstance.get()) == [dg.DagsterRunStatus.FAILURE]
    assert fail_dead_runs(dg.DagsterInstance.get()) == []  # once


def test_a_run_whose_process_lives_is_left_alone():
    instance = dg.DagsterInstance.ephemeral()

    @dg.asset
    def quick() -> int:
        return 1

    job = dg.Definitions(assets=[quick]).resolve_implicit_global_asset_job_def()
    live = instance.create_run_for_job(job, tags=run_tags(), status=dg.DagsterRunStatus.STARTED)
    assert instance.get_run_by_id(live.run_id).status == dg.DagsterRunStatus.STARTED
    assert fail_dead_runs(instance) == []
    assert instance.get_run_by_id(live.run_id).status == dg.DagsterRunStatus.STARTED


def test_process_alive_tells_a_reused_pid_from_the_process_that_ran():
    me = run_tags()
    assert process_alive(os.getpid(), me[START_TAG])
    if me[START_TAG]:  # /proc available: another start time is another process
        assert not process_alive(os.getpid(), str(int(me[START_TAG]) + 1))
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    assert not process_alive(child.pid)
