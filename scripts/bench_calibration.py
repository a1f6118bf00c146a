"""Run time of the camera initialisation (the ``intrinsics`` and ``extrinsics`` assets' library calls) on stored
sequences.

Reads each partition's stored ``detections`` (lifted) and ``views`` artifacts (materialize them first with
``humancal update --partition P``) and times ``estimate_intrinsics`` and ``estimate_extrinsics`` with the
pipeline's settings, single-threaded BLAS, ``--repeats`` times; prints the median and the spread, plus the size
of the input. The lifting itself is timed too (``lift``: the ``detections`` asset, given the checkpoint).

    python scripts/bench_calibration.py [--partition shelf__test --partition synthetic__benchmark] [--repeats 3]

``--save FILE.pkl`` also keeps what the calibration returned (every camera, and the diagnostics but their timings);
``--compare A.pkl B.pkl`` says whether two such files agree: how a change that should not move the cameras (a
refactoring) is checked, with the code before and after it (e.g. a ``git worktree`` of each on ``PYTHONPATH``).
"""

from __future__ import annotations

import argparse
import pickle
import statistics
import time

import numpy as np
import pandas as pd
import threadpoolctl
import torch

from assets.settings import IntrinsicsSettings
from humancal.calibration import ExtrinsicsConfig, estimate_extrinsics, estimate_intrinsics
from humancal.lifter import lift_detections_table, lifted_from_table, load_lifter
from pipelines.definitions import artifacts_root
from resources.io_managers import partition_path


def _read(asset: str, partition: str | None) -> pd.DataFrame:
    path = partition_path(artifacts_root(), asset, partition)
    if not path.exists():
        raise SystemExit(f"bench_calibration: {path} is missing; run `humancal update --partition {partition}` first")
    return pd.read_parquet(str(path))


def _time(fn, repeats: int) -> tuple[float, float, object]:
    seconds, out = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        seconds.append(time.perf_counter() - start)
    return statistics.median(seconds), max(seconds) - min(seconds), out


def _kept(estimate) -> dict:
    """What a comparison looks at: every camera's arrays and the diagnostics, timings left out."""
    diagnostics = estimate.diagnostics
    return {"cameras": [(c.K, c.R_cam_from_world, c.t_cam_from_world_m, c.distortion) for c in estimate.cameras],
            "diagnostics": {name: getattr(diagnostics, name) for name in diagnostics.__dataclass_fields__
                            if name != "timings_s"}}


def compare(path_a: str, path_b: str) -> bool:
    """Print, per partition, the largest camera difference and the diagnostics that differ; True when all agree."""
    a, b = (pickle.loads(open(p, "rb").read()) for p in (path_a, path_b))
    agree = True
    for partition in sorted(set(a) | set(b)):
        if partition not in a or partition not in b:
            print(f"{partition}: only in {'the first' if partition in a else 'the second'} file")
            agree = False
            continue
        worst = max(float(np.max(np.abs(np.asarray(x) - np.asarray(y))))
                    for ca, cb in zip(a[partition]["cameras"], b[partition]["cameras"]) for x, y in zip(ca, cb))
        differ = []
        for name, x in a[partition]["diagnostics"].items():
            y = b[partition]["diagnostics"][name]
            if isinstance(x, pd.DataFrame):
                same = x.equals(y)
            elif isinstance(x, np.ndarray):
                same = np.array_equal(x, y, equal_nan=True)
            else:
                same = repr(x) == repr(y)
            if not same:
                differ.append(name)
        agree &= worst == 0.0 and not differ
        print(f"{partition}: cameras differ by at most {worst:.3g}; diagnostics that differ: {differ or 'none'}")
    return agree


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--partition", action="append", help="stored partition (repeatable)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--save", metavar="FILE.pkl", help="keep the cameras and diagnostics of every partition")
    parser.add_argument("--compare", nargs=2, metavar="FILE.pkl", help="compare two --save files and exit")
    args = parser.parse_args()
    if args.compare:
        raise SystemExit(0 if compare(*args.compare) else 1)
    kept = {}
    partitions = args.partition or ["shelf__test", "synthetic__benchmark"]
    torch.set_num_threads(1)
    checkpoint_path = partition_path(artifacts_root(), "lifter_checkpoint", None, ".pt")
    lifter = load_lifter(str(checkpoint_path)) if checkpoint_path.exists() else None
    rows = []
    for pk in partitions:
        table, views = _read("detections", pk), _read("views", pk)
        dense, lifted = lifted_from_table(table)
        sizes = list(zip(views.sort_values("view")["width_px"], views.sort_values("view")["height_px"]))
        with threadpoolctl.threadpool_limits(1):
            t_int, s_int, intrinsics = _time(lambda: estimate_intrinsics(dense, lifted, sizes, IntrinsicsSettings().to_library()),
                                             args.repeats)
            t_ext, s_ext, extrinsics = _time(lambda: estimate_extrinsics(dense, lifted, intrinsics,
                                                                         ExtrinsicsConfig()), args.repeats)
        kept[pk] = _kept(extrinsics)
        row = {"partition": pk, "views": len(sizes), "frames": int(len(set(dense.frame.tolist()))),
               "detections": len(dense), "intrinsics_s": t_int, "intrinsics_spread_s": s_int,
               "extrinsics_s": t_ext, "extrinsics_spread_s": s_ext}
        if lifter is not None:
            raw = _read("raw_detections", pk)
            row["lift_s"] = _time(lambda: lift_detections_table(lifter, raw, pk), args.repeats)[0]
        rows.append(row)
        print(pd.DataFrame([row]).to_string(index=False, float_format=lambda v: f"{v:.2f}"), flush=True)
    if args.save:
        with open(args.save, "wb") as out:
            pickle.dump(kept, out)
    print("\nmedian of", args.repeats, "runs, seconds, one BLAS and one torch thread:")
    print(pd.DataFrame(rows).to_string(index=False, float_format=lambda v: f"{v:.2f}"))


if __name__ == "__main__":
    main()
