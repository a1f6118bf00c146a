"""What ``humancal demo`` prints after its update: ten headline figures and the seconds per stage, in 80 columns
(``humancal demo --all``: every headline row of the metric table, as ``humancal report`` prints it)."""

from __future__ import annotations

import math
import textwrap

__all__ = ["HEADLINE", "headline_lines"]

HEADLINE = (
    # (stage, method of the metric table, metric, label)
    ("cameras", "int_ext", "focal_error_pct", "focal length error"),
    ("cameras", "int_ext", "position_error_mm", "camera position error"),
    ("cameras", "int_ext", "angle_error_deg", "camera angle error"),
    ("cameras", "int_ext", "reprojection_error_px", "reprojection error"),
    ("cameras", "int_ext", "scale_error_pct", "world scale error"),
    ("association", "association", "pairwise_precision", "pairwise precision"),
    ("association", "association", "pairwise_recall", "pairwise recall"),
    ("association", "association", "idf1", "IDF1"),
    ("bodies", "int_ext", "mpjpe_mm", "MPJPE"),
    ("bodies", "int_ext", "pa_mpjpe_mm", "PA-MPJPE"),
    ("bodies", "int_ext", "pcp_avg", "PCP"),
)
"""The rows of the short table: the final cameras (refined with the bodies, method ``int_ext``; the calibration's,
``init``, when ``final_cameras`` holds those), who is who (``association``), and the fitted bodies (``int_ext``),
against the ground truth of the synthetic scene."""

WIDTH = 80


def headline_lines(partition: str, everything: bool = False) -> list[str]:
    """The demo's figures for ``partition`` from its stored metric table (and the run history's seconds)."""
    from pipelines import cli

    table = cli._stored_metrics([partition], headline_only=True)
    if everything:
        return [_markdown(table)]
    from pipelines.cli.export import final_source

    source = final_source(partition)
    lines = [f"{partition}: final cameras, who is who and bodies against the ground truth", ""]
    lines += _figures(table, "init" if source.startswith("the extrinsics") else "int_ext")
    lines += textwrap.wrap(f"final cameras: {source}", WIDTH, subsequent_indent="  ")
    seconds = _stage_seconds(partition)
    if seconds:
        lines += [""] + textwrap.wrap("seconds per stage: " + ", ".join(f"{n} {s:.1f}" for n, s in seconds),
                                      WIDTH, subsequent_indent="  ")
    lines += ["", "(`humancal demo --all`: every headline row;",
              f" `humancal report --partition {partition} --all`: per view and per joint)"]
    return lines


def _markdown(table) -> str:
    import io
    import sys

    from pipelines import cli

    buffer, saved = io.StringIO(), sys.stdout
    sys.stdout = buffer
    try:
        cli._print_metrics(table, "md")
    finally:
        sys.stdout = saved
    return buffer.getvalue().rstrip("\n")


def _figures(table, camera_method: str = "int_ext") -> list[str]:
    rows = []
    for stage, method, metric, label in HEADLINE:
        method = camera_method if stage == "cameras" else method
        found = table[(table["method"] == method) & (table["metric"] == metric)]
        if found.empty:
            continue
        value, unit = float(found["value"].iloc[0]), str(found["unit"].iloc[0])
        if unit == "ratio":  # precision and recall read better in per cent
            value, unit = 100.0 * value, "%"
        flag = found["failed_checks"].iloc[0] if "failed_checks" in found.columns else None
        marked = isinstance(flag, str) and flag != ""
        rows.append((stage, label, f"{value:.2f}", unit, f" (failed checks: {flag})" if marked else ""))
    if not rows:
        return ["(no headline figure in the metric table: `humancal demo --all` prints all of it)"]
    head = ("stage", "figure", "value", "unit")
    widths = [max(len(r[i]) for r in [head, *rows]) for i in range(4)]
    fmt = "| {:<%d} | {:<%d} | {:>%d} | {:<%d} |" % tuple(widths)
    rule = "|" + "|".join("-" * (w + 2) for w in widths[:2]) + f"|{'-' * (widths[2] + 1)}:|{'-' * (widths[3] + 2)}|"
    return [fmt.format(*head), rule, *(fmt.format(*r[:4]) + r[4] for r in rows)]


def _stage_seconds(partition: str) -> list[tuple[str, float]]:
    """(step, seconds) of the latest materialization of each step on the method's path, then the total."""
    from assets.timings import TOTAL, stage_timings_table, timed_graph
    from pipelines import cli
    from pipelines.definitions import defs

    graph = timed_graph(defs.resolve_all_asset_specs())
    table = stage_timings_table(cli._instance(), graph, [partition])
    out, seen = [], set()
    for asset in graph.assets:
        if asset not in graph.path:
            continue
        rows = table[table["asset"] == asset]
        if rows.empty or rows["step"].iloc[0] in seen or not math.isfinite(rows["seconds"].iloc[0]):
            continue
        seen.add(rows["step"].iloc[0])
        out.append((rows["step"].iloc[0] or asset, float(rows["seconds"].iloc[0])))
    total = table[table["asset"] == TOTAL]["seconds"]
    if len(total) and math.isfinite(total.iloc[0]):
        out.append(("total", float(total.iloc[0])))
    return out
