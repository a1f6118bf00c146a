"""What the sweep scripts share: run the scenes in worker processes, write the long table, print each method's
median and mean of every figure (``scripts/body_sweep.py``, ``scripts/refinement_sweep.py``)."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pandas as pd


def run_and_summarise(run_scene: Callable, jobs: Iterable, workers: int, metrics: Iterable[str],
                      csv_path: Path) -> pd.DataFrame:
    """Run ``run_scene`` on every job in ``workers`` processes, write the concatenated long table (columns scene,
    method, metric, value, ...) to ``csv_path``, print the medians and means per method, and return the figures of
    ``metrics`` as a wide table (scenes x (method, metric))."""
    with ProcessPoolExecutor(max_workers=workers) as pool:
        table = pd.concat(list(pool.map(run_scene, list(jobs))), ignore_index=True)
    csv_path.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(csv_path, index=False)
    figures = table[table["metric"].isin(list(metrics))]
    summary = figures.groupby(["method", "metric"])["value"].agg(["median", "mean"]).unstack("metric")
    print("\nover all scenes (median, then mean):")
    print(summary["median"].round(2).to_string())
    print(summary["mean"].round(2).to_string())
    print(f"written {csv_path}")
    return figures.pivot_table(index="scene", columns=["method", "metric"], values="value", aggfunc="first")
