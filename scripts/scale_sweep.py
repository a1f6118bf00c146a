"""How the graph's time and memory grow with frames, views and people: synthetic captures of growing size, each
timed from the detections to the metric tables by ``scripts/bench_graph.py --scene`` in a fresh process.

    python scripts/scale_sweep.py [--points NAME ...] [--timeout-s 3600] [--max-rss-gb 16] [--out DIR]

Each point is the ``benchmark`` scene (a ring of cameras, 30 fps) with some of its sizes changed. Prints, per
point, each stage's seconds and the process's peak resident memory while it ran, and writes every point's JSON
and the table (``scale_sweep.md``) to ``--out``. A point that fails, runs past ``--timeout-s`` or holds more than
``--max-rss-gb`` of memory (it is stopped there) is reported as such and the sweep goes on. Restrict it to two
cores to measure against the 2-core target:
``taskset -c 0,1 python scripts/scale_sweep.py``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import psutil

REPO = Path(__file__).resolve().parent.parent

POINTS = {  # name -> (views, people, frames)
    "reference": (5, 4, 900),
    "frames_2700": (5, 4, 2700),
    "frames_9000": (5, 4, 9000),
    "views_10": (10, 4, 900),
    "views_31": (31, 4, 900),
    "people_8": (5, 8, 900),
    "all_300": (31, 8, 300),
    "all_900": (31, 8, 900),
    "all_9000": (31, 8, 9000),
}
"""The sweep: the reference workload, each axis alone, then all of them (31 views x 8 people x 5 min at 30 fps)."""

STAGES = {  # column -> the asset whose step it is (bench_graph's JSON)
    "lifting": "detections", "intrinsics": "intrinsics", "extrinsics": "extrinsics",
    "association": "associations", "body fit": "fitted_motions", "metric tables": "metric_tables",
}


def _parse(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--points", nargs="+", default=list(POINTS), choices=list(POINTS), metavar="NAME",
                        help=f"which points, in order (default: all: {', '.join(POINTS)})")
    parser.add_argument("--timeout-s", type=float, default=3600.0, help="the most one point may take, seconds")
    parser.add_argument("--max-rss-gb", type=float, default=16.0,
                        help="stop a point whose process holds more resident memory than this, GB")
    parser.add_argument("--out", type=Path, default=Path("scale_sweep"), help="where the JSON and the table go")
    return parser.parse_args(argv)


def run_point(name: str, out: Path, timeout_s: float, max_rss_gb: float) -> dict:
    """bench_graph on one point; its JSON, or ``{"error": ...}``."""
    views, people, frames = POINTS[name]
    scene = {"preset": "benchmark", "num_views": views, "num_people": people, "num_frames": frames}
    result = out / f"{name}.json"
    log = out / f"{name}.log"
    start = time.perf_counter()
    with log.open("w") as stream:
        process = subprocess.Popen([sys.executable, str(REPO / "scripts" / "bench_graph.py"), "--scene",
                                    json.dumps(scene), "--json", str(result)], stdout=stream, stderr=subprocess.STDOUT)
        watched = psutil.Process(process.pid)
        while process.poll() is None:
            try:
                rss_gb = watched.memory_info().rss / 2**30
            except psutil.NoSuchProcess:
                rss_gb = 0.0
            over = ("ran past {:.0f} s".format(timeout_s) if time.perf_counter() - start > timeout_s else
                    f"stopped at {rss_gb:.1f} GB of memory (more than {max_rss_gb:g})" if rss_gb > max_rss_gb else None)
            if over:
                process.kill()
                process.wait()
                return {"error": over}
            time.sleep(0.5)
    if process.returncode != 0 or not result.exists():
        return {"error": f"exit status {process.returncode} (see {log})"}
    figures = json.loads(result.read_text())
    figures["process_s"] = time.perf_counter() - start
    return figures


def table(results: dict[str, dict]) -> str:
    """The markdown table: per point, each stage's seconds / peak MB, the total and the peak."""
    head = ["point", "views x people x frames", *STAGES, "detections -> metric tables", "peak RSS"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, figures in results.items():
        views, people, frames = POINTS[name]
        cells = [name, f"{views} x {people} x {frames}"]
        if "error" in figures:
            cells += [figures["error"]] + [""] * (len(head) - 3)
        else:
            for asset in STAGES.values():
                step = figures["step_of_asset"].get(asset)
                seconds = figures["seconds"].get(asset, float("nan"))
                mb = figures["step_peak_rss_mb"].get(step, float("nan"))
                cells.append(f"{seconds:.1f} s / {mb / 1024:.1f} GB")
            cells += [f"{figures['total_s']:.1f} s", f"{figures['peak_rss_mb'] / 1024:.1f} GB"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    args = _parse(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    results: dict[str, dict] = {}
    for name in args.points:
        print(f"{name}: {' x '.join(map(str, POINTS[name]))} (views x people x frames) ...", flush=True)
        results[name] = run_point(name, args.out, args.timeout_s, args.max_rss_gb)
        figures = results[name]
        print(f"  {figures['error']}" if "error" in figures else
              f"  detections -> metric tables {figures['total_s']:.1f} s, peak {figures['peak_rss_mb']:.0f} MB "
              f"(the process {figures['process_s']:.0f} s, scene generation included)", flush=True)
        (args.out / "scale_sweep.md").write_text(table(results))
    print()
    print(table(results))
    return 0 if all("error" not in f for f in results.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
