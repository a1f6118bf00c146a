"""Cold timing of the per-sequence graph, from the detections to the metric tables, on one partition.

    python scripts/bench_graph.py [--partition synthetic__benchmark] [--threads N] [--with-method-tables] [--keep DIR]
                                  [--scene JSON] [--json FILE]

In a fresh temporary state dir (no stored artifact, no run history; only anny's body-model cache,
``ANNY_CACHE_DIR``, is reused), in-process: materializes ``lifter_checkpoint`` (the shipped weights), then, in one
run, every per-sequence asset that ``metric_tables`` needs for the partition, with their asset checks, as
``dagster asset materialize --select ... --partition P`` would (``humancal update`` runs the same steps level by
level, one run per level). It then prints each asset's seconds from the run's step stats (the function of the
``stage_timings`` asset) and the process's peak resident memory while its step ran (sampled every 50 ms), the
total from ``detections`` to ``metric_tables`` (the method's path: neither the inputs and ground truth nor the
references computed from them), and the wall time of the run.

``--scene`` times a synthetic capture of any size instead: the options of a synthetic sequence (as in a datasets
file, e.g. ``'{"preset": "benchmark", "num_views": 31, "num_people": 8, "num_frames": 9000}'``), registered as
dataset ``scale`` in the fresh state dir (``scripts/scale_sweep.py`` runs a series of them).

The performance target (``shared/DESIGN.md`` section 7) is the reference workload, ``synthetic__benchmark``
(900 frames, 5 views, 4 people: the default); ``synthetic__demo`` is the same scene size over 300 frames. Restrict
the process to two cores to measure against the 2-core target: ``taskset -c 0,1 python scripts/bench_graph.py``.
torch uses the threads of the ``torch_runtime`` resource (by default torch's own setting: one per physical core).
"""

import argparse
import json
import os
import shutil
import sys
import tempfile
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
QUIET = {"loggers": {"console": {"config": {"log_level": "WARNING"}}}}


def _parse(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--partition", default="synthetic__benchmark", help="the partition to time")
    parser.add_argument("--with-method-tables", action="store_true",
                        help="also time method_tables (the paper's other regimes: several full fits), in a second run")
    parser.add_argument("--threads", type=int, default=None,
                        help="torch intra-op threads (the torch_runtime resource; default: torch's own setting, "
                             "one per physical core)")
    parser.add_argument("--scene", default=None, metavar="JSON",
                        help="time a synthetic capture with these options (module docstring) instead of --partition")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures to this JSON file")
    parser.add_argument("--keep", type=Path, default=None,
                        help="keep the state dir here (artifacts and the instance) instead of a temporary one")
    return parser.parse_args(argv)


def main(argv=None) -> int:
    args = _parse(argv)
    os.environ.setdefault("ANNY_CACHE_DIR", str(REPO / ".humancal" / "cache" / "anny"))
    state = args.keep or Path(tempfile.mkdtemp(prefix="humancal-bench-graph-"))
    state.mkdir(parents=True, exist_ok=True)
    os.environ["HUMANCAL_STATE_DIR"] = str(state)
    os.environ["DAGSTER_HOME"] = str(state / "dagster_home")
    (state / "dagster_home").mkdir(exist_ok=True)
    (state / "dagster_home" / "dagster.yaml").write_text("telemetry:\n  enabled: false\n")
    if args.scene is not None:
        args.partition = _register_scene(state, args.scene)
    sys.path.insert(0, str(REPO))
    try:
        return _run(args, state)
    finally:
        if args.keep is None:
            shutil.rmtree(state, ignore_errors=True)


def _register_scene(state: Path, scene: str) -> str:
    """Write the state dir's datasets file with one synthetic capture of options ``scene`` (JSON); its partition."""
    try:
        options = json.loads(scene)
    except json.JSONDecodeError as error:
        raise SystemExit(f"bench_graph: --scene must be a JSON object of synthetic scene options ({error})")
    if not isinstance(options, dict):
        raise SystemExit(f"bench_graph: --scene must be a JSON object of synthetic scene options, got {scene!r}")
    name = "_".join(f"{k}{v}" for k, v in sorted(options.items()) if k != "preset").replace(".", "p") or "default"
    name = "".join(c if c.isalnum() or c == "_" else "_" for c in f"{options.get('preset', 'demo')}_{name}")
    (state / "datasets.yaml").write_text(f"datasets:\n  scale:\n    kind: synthetic\n    sequences:\n"
                                         f"      {name}: {json.dumps(options)}\n")
    return f"scale__{name}"


class MemorySampler:
    """The process's resident memory (``/proc/self/status`` VmRSS), sampled every ``interval_s`` on a thread; the
    peak between two wall-clock times (``time.time()``) is :meth:`peak_mb`."""

    def __init__(self, interval_s: float = 0.05) -> None:
        self.samples: list[tuple[float, float]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._sample, args=(interval_s,), daemon=True)

    def __enter__(self) -> "MemorySampler":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()

    def _sample(self, interval_s: float) -> None:
        while not self._stop.is_set():
            self.samples.append((time.time(), _rss_mb()))
            self._stop.wait(interval_s)

    def peak_mb(self, start: float | None = None, end: float | None = None) -> float:
        inside = [mb for t, mb in self.samples if (start is None or t >= start) and (end is None or t <= end)]
        return max(inside) if inside else float("nan")


def _rss_mb() -> float:
    """Resident memory of this process now, MB (Linux; NaN elsewhere)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float("nan")


def _run(args, state: Path) -> int:
    with MemorySampler() as memory:
        return _timed_run(args, state, memory)


def _timed_run(args, state: Path, memory: MemorySampler) -> int:
    import dagster as dg

    from assets.timings import stage_timings_table, timed_graph
    from evaluation.benchmark import stage_timings_markdown
    from evaluation.paper_results import paper_results
    from pipelines.definitions import build_definitions
    from pipelines.partitions import SEQUENCES

    defs = build_definitions(str(state / "artifacts"))
    if args.partition not in {spec.key for spec in defs.resources["datasets"].available()}:
        raise SystemExit(f"bench_graph: unknown or unavailable partition {args.partition}")
    instance = dg.DagsterInstance.get()
    instance.add_dynamic_partitions(SEQUENCES.name, [args.partition])
    graph = defs.resolve_asset_graph()
    checks = list(getattr(defs, "asset_checks", None) or [])

    run_config = dict(QUIET)
    if args.threads is not None:
        run_config["resources"] = {"torch_runtime": {"config": {"threads": args.threads}}}

    def materialize(keys, partition=None):
        start = time.perf_counter()
        result = dg.materialize([*defs.assets, *checks], resources=defs.resources, instance=instance,
                                selection=dg.AssetSelection.assets(*keys), partition_key=partition,
                                run_config=run_config, raise_on_error=False)
        seconds = time.perf_counter() - start
        if not result.success:
            failed = [e.step_key for e in result.get_step_failure_events()]
            raise SystemExit(f"bench_graph: the run failed (steps {failed}); see the log above")
        return seconds

    needed, todo = set(), [dg.AssetKey("metric_tables")]
    while todo:  # metric_tables and everything upstream of it
        key = todo.pop()
        if key not in needed:
            needed.add(key)
            todo.extend(graph.get(key).parent_keys)
    shared = sorted((k for k in needed if graph.get(k).partitions_def is None), key=lambda k: k.to_user_string())
    partitioned = sorted((k for k in needed if graph.get(k).partitions_def is not None),
                         key=lambda k: k.to_user_string())
    print(f"{args.partition}: fresh state dir {state}; {os.cpu_count()} CPU(s) visible, "
          f"{len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else '?'} usable", flush=True)
    print(f"shared inputs first: {', '.join(k.to_user_string() for k in shared)} ...", flush=True)
    shared_s = materialize(shared)
    print(f"  {shared_s:.1f} s", flush=True)
    print(f"then {len(partitioned)} per-sequence assets in one run ...", flush=True)
    wall = materialize(partitioned, args.partition)
    if args.with_method_tables:
        print("then method_tables ...", flush=True)
        wall_methods = materialize([dg.AssetKey("method_tables")], args.partition)
    timings = stage_timings_table(instance, timed_graph(defs.resolve_all_asset_specs()), [args.partition])
    peaks = _step_peaks(instance, timings, memory)
    print()
    print(stage_timings_markdown(timings, paper_results()))
    total = timings.loc[timings["asset"] == "total", "seconds"].item()
    print("peak resident memory of the process while each step ran, MB: "
          + ", ".join(f"{step} {mb:.0f}" for step, mb in peaks.items()))
    print(f"{args.partition}: detections -> metric_tables {total:.1f} s (sum of the method's steps); the run's wall "
          f"time {wall:.1f} s (every step it needed, loading and checks included); peak memory "
          f"{memory.peak_mb():.0f} MB"
          + (f"; method_tables run {wall_methods:.1f} s" if args.with_method_tables else ""))
    if args.json is not None:
        seconds = {row.asset: row.seconds for row in timings.itertuples()}
        args.json.write_text(json.dumps({
            "partition": args.partition, "scene": json.loads(args.scene) if args.scene else None,
            "seconds": seconds, "step_peak_rss_mb": peaks,
            "step_of_asset": dict(zip(timings["asset"], timings["step"])),
            "total_s": total, "wall_s": wall, "peak_rss_mb": memory.peak_mb()}, indent=1))
    return 0


def _step_peaks(instance, timings, memory: MemorySampler) -> dict[str, float]:
    """step key -> the process's peak resident memory while that step of the timed run ran, MB."""
    peaks = {}
    for run_id in timings["run_id"].dropna().unique():
        for stats in instance.get_run_step_stats(run_id):
            if stats.start_time is not None and stats.end_time is not None:
                peaks[stats.step_key] = memory.peak_mb(stats.start_time, stats.end_time)
    return peaks


if __name__ == "__main__":
    sys.exit(main())
