"""A humancal cluster on this machine: Redis, Postgres and Celery workers, with a batch of synthetic captures.

Starts Debian's ``redis-server`` (the broker) and a throwaway Postgres cluster (the Dagster instance), registers
``--partitions`` synthetic captures in a fresh state dir, starts ``--workers`` ``humancal worker`` processes and
runs ``humancal update`` over the batch. With ``--kill-after S``, one worker is killed (``kill -9``, the whole
process group) S seconds into the update. Then ``humancal update`` runs again and must find nothing to do.
Everything is stopped and the temporary folder removed at the end (``--keep DIR`` works in DIR and keeps it).

    python scripts/local_cluster.py --workers 2 --partitions 12 --kill-after 60
    python scripts/local_cluster.py --workers 1 --partitions 12 --json one_worker.json
    python scripts/local_cluster.py --workers 0 --partitions 12     # the baseline: no cluster, steps in-process

Prints a summary (and writes it as JSON with ``--json``): partitions per minute, the lines of both updates, which
worker was killed. Exit status 1 when a partition was not materialized or the second update did anything.

Needs ``redis-server`` and PostgreSQL's ``initdb``/``pg_ctl`` (Debian: ``apt-get install redis-server postgresql``)
and the cluster extra (``pip install -e '.[cluster]'``). As root, Postgres runs as the ``postgres`` user.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from contextlib import ExitStack, contextmanager
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
HUMANCAL = [sys.executable, "-m", "pipelines.cli"]
SCENE = {"preset": "tiny", "num_people": 3, "num_views": 4, "num_frames": 40}
"""The synthetic captures of the batch: the ``synthetic__tiny`` scene with one seed each."""
SEEDS = (101, 102, 103, 104, 105, 106, 107, 108, 109, 111, 112, 113, 114, 115, 116, 117)
"""Seeds whose scene calibrates: of seeds 100-121, 100, 110 and 118 are stopped by ``focal_constrained`` (40 frames of
3 people in 4 views are few), which is the calibration's business, not the cluster's."""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait(what: str, ready, timeout_s: float = 60.0, proc: subprocess.Popen | None = None) -> None:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if ready():
            return
        if proc is not None and proc.poll() is not None:
            raise RuntimeError(f"{what} exited with status {proc.returncode} before it was ready")
        time.sleep(0.2)
    raise RuntimeError(f"{what} was not ready after {timeout_s:.0f} s")


def _port_open(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


@contextmanager
def redis_server(folder: Path):
    """A Redis server on a free port, no persistence; yields its URL."""
    exe = shutil.which("redis-server")
    if exe is None:
        raise RuntimeError("redis-server not found (Debian: apt-get install redis-server)")
    port = free_port()
    proc = subprocess.Popen([exe, "--port", str(port), "--bind", "127.0.0.1", "--save", "", "--appendonly", "no",
                             "--dir", str(folder)], stdout=open(folder / "redis.log", "w"), stderr=subprocess.STDOUT)
    try:
        _wait("redis-server", lambda: _port_open(port), proc=proc)
        yield f"redis://127.0.0.1:{port}/0"
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def _postgres_bin(name: str) -> str:
    found = shutil.which(name)
    if found:
        return found
    for folder in sorted(Path("/usr/lib/postgresql").glob("*/bin"), reverse=True):
        if (folder / name).exists():
            return str(folder / name)
    raise RuntimeError(f"PostgreSQL's {name} not found (Debian: apt-get install postgresql)")


@contextmanager
def postgres_server(folder: Path):
    """A throwaway Postgres cluster in ``folder`` on a free port (trust auth on localhost); yields the URL of its
    database ``humancal``. As root, the cluster is owned by and runs as the ``postgres`` user."""
    data, sockets = folder / "pgdata", folder / "pgsock"
    sockets.mkdir()
    as_user: list[str] = []
    if os.geteuid() == 0:
        as_user = ["runuser", "-u", "postgres", "--"]
        shutil.chown(folder, "postgres")
        shutil.chown(sockets, "postgres")
    port = free_port()
    log = folder / "postgres.log"
    done = subprocess.run([*as_user, _postgres_bin("initdb"), "-D", str(data), "-U", "humancal", "--auth=trust",
                           "--no-sync", "-E", "UTF8"], capture_output=True, text=True)
    if done.returncode:
        raise RuntimeError(f"initdb failed: {(done.stderr or done.stdout).strip()}")
    subprocess.run([*as_user, _postgres_bin("pg_ctl"), "-D", str(data), "-l", str(log), "-w", "-o",
                    f"-p {port} -k {sockets} -c listen_addresses=127.0.0.1 -c fsync=off", "start"],
                   check=True, capture_output=True)
    try:
        subprocess.run([*as_user, _postgres_bin("createdb"), "-h", "127.0.0.1", "-p", str(port), "-U", "humancal",
                        "humancal"], check=True, capture_output=True)
        yield f"postgresql://humancal@127.0.0.1:{port}/humancal"
    finally:
        subprocess.run([*as_user, _postgres_bin("pg_ctl"), "-D", str(data), "-m", "fast", "-w", "stop"],
                       capture_output=True)


def start_worker(name: str, env: dict[str, str], folder: Path, threads: int) -> subprocess.Popen:
    """``humancal worker`` in its own process group (so that it can be killed whole); waits until it is ready."""
    log = folder / f"worker_{name}.log"
    proc = subprocess.Popen([*HUMANCAL, "worker", "--name", f"{name}@%h", "--threads", str(threads)], env=env, cwd=REPO,
                            stdout=open(log, "w"), stderr=subprocess.STDOUT, start_new_session=True)
    _wait(f"worker {name} (log: {log})", lambda: " ready." in log.read_text(), timeout_s=120, proc=proc)
    return proc


def stop(proc: subprocess.Popen, kill: bool = False) -> None:
    """Stop a process group: SIGTERM and a wait, or ``kill -9``."""
    if proc.poll() is not None:
        return
    try:
        os.killpg(proc.pid, signal.SIGKILL if kill else signal.SIGTERM)
        proc.wait(timeout=60)
    except (ProcessLookupError, subprocess.TimeoutExpired):
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()


def write_batch(state: Path, count: int) -> list[str]:
    """The user datasets file of the state dir: dataset ``batch`` with ``count`` synthetic captures (seeds
    :data:`SEEDS`, then on from the last); returns their partition keys."""
    seeds = [*SEEDS, *range(SEEDS[-1] + 1, SEEDS[-1] + 1 + max(0, count - len(SEEDS)))][:count]
    names = [f"s{seed}" for seed in seeds]
    lines = ["datasets:", "  batch:", "    kind: synthetic", "    sequences:"]
    lines += [f"      {n}: {json.dumps({**SCENE, 'seed': seed})}" for n, seed in zip(names, seeds)]
    (state / "datasets.yaml").write_text("\n".join(lines) + "\n")
    return [f"batch__{n}" for n in names]


def busy(log: Path) -> bool:
    """Whether the worker writing ``log`` is running a step now: a task it received and has not ended."""
    text = log.read_text()
    received = set(re.findall(r"Task execute_plan\[([0-9a-f-]+)\] received", text))
    ended = set(re.findall(r"Task execute_plan\[([0-9a-f-]+)\] (?:succeeded|raised|retry)", text))
    return bool(received - ended)


def humancal_update(partitions: list[str], env: dict[str, str], kill=None) -> tuple[int, list[str], float]:
    """``humancal update --partition ...``: its exit status, its output lines and its seconds. ``kill``:
    ``(seconds, when, callable)``: the callable is called once, the first time ``when()`` holds that many seconds
    in or later."""
    argv = [*HUMANCAL, "update", *[a for p in partitions for a in ("--partition", p)]]
    t0 = time.monotonic()
    proc = subprocess.Popen(argv, env=env, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines, killed = [], kill is None
    os.set_blocking(proc.stdout.fileno(), False)
    while True:
        chunk = proc.stdout.readline()
        if chunk:
            lines.append(chunk.rstrip("\n"))
            print(f"  | {lines[-1]}", flush=True)
            continue
        if proc.poll() is not None:
            rest = proc.stdout.read() or ""
            lines += rest.splitlines()
            break
        if not killed and time.monotonic() - t0 >= kill[0] and kill[1]():
            kill[2]()
            killed = True
        time.sleep(0.1)
    return proc.returncode, lines, time.monotonic() - t0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=int, default=2,
                        help="Celery workers; 0: no cluster at all, every step in the humancal process (the baseline)")
    parser.add_argument("--partitions", type=int, default=12)
    parser.add_argument("--kill-after", type=float, default=None,
                        help="kill -9 the first worker this many seconds into the update, as soon as it runs a step")
    parser.add_argument("--no-postgres", action="store_true", help="keep the instance in SQLite (one machine)")
    parser.add_argument("--json", type=Path, default=None, help="write the summary here")
    parser.add_argument("--keep", type=Path, default=None,
                        help="a new folder to work in and keep (state/, services/ with the workers' logs)")
    args = parser.parse_args(argv)
    if args.workers < 0 or args.partitions < 1:
        parser.error("--workers must be >= 0 and --partitions >= 1")
    if args.kill_after is not None and args.workers < 2:
        parser.error("--kill-after needs --workers 2 or more (a worker must be left to finish)")

    with ExitStack() as stack:
        if args.keep:
            folder = args.keep.resolve()
            folder.mkdir(parents=True, exist_ok=False)
        else:
            folder = Path(tempfile.mkdtemp(prefix="humancal_cluster_"))
            folder.chmod(0o755)  # as root, Postgres runs as the postgres user, who must reach services/
            stack.callback(shutil.rmtree, folder, ignore_errors=True)
        state, services = folder / "state", folder / "services"
        state.mkdir()
        services.mkdir()
        env = dict(os.environ, HUMANCAL_STATE_DIR=str(state),
                   ANNY_CACHE_DIR=os.environ.get("ANNY_CACHE_DIR", str(REPO / ".humancal" / "cache" / "anny")))
        for name in ("HUMANCAL_CELERY_BROKER", "HUMANCAL_CELERY_BACKEND", "HUMANCAL_POSTGRES_URL"):
            env.pop(name, None)
        broker = None
        if args.workers:
            broker = env["HUMANCAL_CELERY_BROKER"] = stack.enter_context(redis_server(services))
            env["HUMANCAL_CELERY_VISIBILITY_TIMEOUT_S"] = os.environ.get("HUMANCAL_CELERY_VISIBILITY_TIMEOUT_S", "120")
            if not args.no_postgres:
                env["HUMANCAL_POSTGRES_URL"] = stack.enter_context(postgres_server(services))
        partitions = write_batch(state, args.partitions)
        print(f"broker {broker or 'none (steps in the humancal process)'}; "
              f"instance {env.get('HUMANCAL_POSTGRES_URL', 'SQLite in the state dir')}; "
              f"state {state}; {len(partitions)} partitions", flush=True)
        workers, threads = [], max(1, (os.cpu_count() or 1) // max(1, args.workers))  # each its share of the cores
        for i in range(args.workers):
            workers.append(start_worker(f"w{i + 1}", env, services, threads))
            stack.callback(stop, workers[-1])
        print(f"{len(workers)} workers ready, {threads} threads each", flush=True)
        killed = []

        def kill_first():
            stop(workers[0], kill=True)
            killed.append("w1")
            print("  * killed worker w1 in the middle of a step (kill -9, its whole process group)", flush=True)

        first_log = services / "worker_w1.log"
        kill = None if args.kill_after is None else (args.kill_after, lambda: busy(first_log), kill_first)
        status, lines, seconds = humancal_update(partitions, env, kill)
        again_status, again, _ = humancal_update(partitions, env)
        materialized = [int(m.group(1)) for line in again for m in [re.match(r"materialized (\d+) asset", line)] if m]
        summary = {
            "workers": args.workers, "partitions": len(partitions), "postgres": "HUMANCAL_POSTGRES_URL" in env,
            "killed": killed, "first_update": {"status": status, "seconds": round(seconds, 1), "lines": lines},
            "partitions_per_minute": round(len(partitions) / seconds * 60, 2),
            "second_update": {"status": again_status, "lines": again,
                              "materialized": materialized[0] if materialized else None},
        }
    print(json.dumps({k: v for k, v in summary.items() if k not in ("first_update", "second_update")}))
    print(f"first update: exit {status} in {seconds:.1f} s; second: exit {again_status}, "
          f"{summary['second_update']['materialized']} asset partitions materialized")
    if args.json:
        args.json.write_text(json.dumps(summary, indent=1))
    ok = status == 0 and again_status == 0 and summary["second_update"]["materialized"] == 0
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
