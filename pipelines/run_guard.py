"""Runs left "started" by a killed ``humancal`` process are marked failed.

``humancal`` launches its runs in its own process (``dg.materialize``), and such runs have no run monitoring: a
process killed with ``kill -9`` (or by the out-of-memory killer, or a power cut) leaves its run STARTED in the
instance for ever, and the Dagster UI shows it in progress. Every run ``humancal`` launches carries tags naming
its process: the host, the pid and the process's start time (``/proc/<pid>/stat``, so that a pid reused by another
process is not taken for it). Every command that opens the instance (``pipelines.cli``) looks at the runs that are
not finished and marks failed those whose process is gone (``instance.report_run_failed``, public API). A run
without these tags (launched by ``dagster dev``, a daemon, or the plain Dagster CLI) or from another host is left
alone: nothing here can tell whether it is still running.
"""

from __future__ import annotations

import os
import socket
from pathlib import Path

__all__ = ["HOST_TAG", "PID_TAG", "START_TAG", "fail_dead_runs", "process_alive", "run_tags"]

PID_TAG = "humancal/pid"
HOST_TAG = "humancal/host"
START_TAG = "humancal/process_start"


def _start_time(pid: int) -> str | None:
    """The start time of process ``pid`` in clock ticks since boot (``None`` where /proc is not available)."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = text[text.rfind(")") + 2:].split()  # after the command name, which may hold spaces
    return fields[19] if len(fields) > 19 else None


def _zombie(pid: int) -> bool:
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return text[text.rfind(")") + 2:].split()[:1] == ["Z"]


def run_tags() -> dict[str, str]:
    """The tags naming this process, for every run it launches."""
    pid = os.getpid()
    return {PID_TAG: str(pid), HOST_TAG: socket.gethostname(), START_TAG: _start_time(pid) or ""}


def process_alive(pid: int, start: str | None = None) -> bool:
    """Whether process ``pid`` (started at ``start``, when known) still runs on this host."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass  # it exists, owned by someone else
    if _zombie(pid):
        return False
    current = _start_time(pid)
    return not (start and current is not None and current != start)


def fail_dead_runs(instance) -> list[str]:
    """Mark failed the unfinished runs launched by a ``humancal`` process of this host that is gone; returns one
    line per run marked."""
    import dagster as dg

    statuses = [dg.DagsterRunStatus.NOT_STARTED, dg.DagsterRunStatus.STARTING, dg.DagsterRunStatus.STARTED]
    host, lines = socket.gethostname(), []
    for record in instance.get_run_records(filters=dg.RunsFilter(statuses=statuses)):
        run = record.dagster_run
        pid = run.tags.get(PID_TAG)
        if pid is None or run.tags.get(HOST_TAG) != host or not pid.isdigit():
            continue
        if process_alive(int(pid), run.tags.get(START_TAG)):
            continue
        message = (f"the humancal process {pid} that ran it ended before the run did (killed?); "
                   "marked failed by the next humancal command")
        try:
            instance.report_run_failed(run, message=message)
        except Exception as err:  # e.g. a read-only instance: say so, and let the command go on
            lines.append(f"run {run.run_id[:8]} of the ended process {pid} could not be marked failed: "
                         f"{str(err).splitlines()[0] if str(err) else type(err).__name__}")
            continue
        lines.append(f"marked run {run.run_id[:8]} failed: its process {pid} ended before the run did (killed?)")
    return lines
