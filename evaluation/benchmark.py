"""The benchmark table: every sequence's headline figures beside the paper's and the peers', and its markdown.

:func:`benchmark_table` builds one long table (canonical table ``benchmark``, ``humancal/tables/schemas.py``) from whatever
metric rows exist: no method or metric is required, so a method that was not run (a prior ablation without its
weights) is simply absent and its cells are blank. ``source`` says who measured a figure:

* ``humancal``: our methods (the ``metric_tables`` and ``method_tables`` rows of the sequence);
* a baseline measured in the graph by another technique (:data:`BASELINE_SOURCES`, e.g. ``epipolar``), or a peer
  tool measured here by hand (``evaluation/peer_results.csv``, e.g. ``pose2sim``);
* ``paper``: the published numbers (``evaluation/paper_results.csv``), per dataset (``sequence`` null).

:func:`benchmark_markdown` lays it out side by side in the sections of :data:`SECTIONS` (which metrics and which
methods each shows: a declared structure, edit it there); :func:`stage_timings_markdown` renders the per-stage
timing table.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import pandas as pd

from humancal.tables.schemas import SCHEMAS, validate_table

__all__ = [
    "BASELINE_SOURCES",
    "SECTIONS",
    "Section",
    "benchmark_markdown",
    "benchmark_table",
    "normalise_metrics",
    "stage_timings_markdown",
]

HUMANCAL = "humancal"
PAPER = "paper"
KEY = ["dataset", "sequence", "method", "metric"]

BASELINE_SOURCES: dict[str, str] = {
    "gt_camera_triangulation": "dlt",  # confidence-weighted DLT with the true cameras and identities
    "epipolar_only": "epipolar",  # the geometric (epipolar/Plücker) affinity alone, same pipeline otherwise
    "epipolar_only_gt_cameras": "epipolar",
}
"""Methods of the metric tables that are another technique measured in the graph, not humancal's method: their
figures carry this source instead of ``humancal``."""


@dataclass(frozen=True)
class Section:
    """One section of the markdown: a table per dataset (and per sequence of ours) with methods as rows.

    Attributes:
        title: the heading.
        datasets: the datasets shown, in order (a dataset without any figure is left out).
        metrics: the columns, in order; for each, the figure measured here and, with ``compare``, the paper's.
        methods: our rows, in order (None: every method measured here with a figure in ``metrics``).
        paper_peers: also the paper's rows for other works (after ours, in the paper's order).
        peers_here: also the baselines and peer tools measured here (after ours, by name).
        compare: show the paper's figure beside ours.
    """

    title: str
    datasets: tuple[str, ...]
    metrics: tuple[str, ...]
    methods: tuple[str, ...] | None = None
    paper_peers: bool = False
    peers_here: bool = False
    compare: bool = True


CAMERA_METRICS = ("focal_error_pct", "position_error_mm", "angle_error_deg", "reprojection_error_px")
BODY_METRICS = ("mpjpe_mm", "pa_mpjpe_mm", "pcp_avg", "accel_error_mm_s2", "pve_mm")
PRIOR_ABLATIONS = ("no_local_linear", "basic_gru", "no_skip")

SECTIONS: tuple[Section, ...] = (
    Section("Cameras", ("shelf", "panoptic"), CAMERA_METRICS,
            methods=("init", "separate", "ext", "int_ext", "int_ext_no_bundle", "int_ext_known_pp", "per_frame_prior",
                     "no_prior", *PRIOR_ABLATIONS, "gt_cameras", "convention_floor"),
            paper_peers=True),
    Section("PCP", ("shelf", "campus"), ("pcp_actor1", "pcp_actor2", "pcp_actor3", "pcp_avg", "mpjpe_mm"),
            methods=("gt_cameras", "ext", "int_ext", "int_ext_no_bundle", "int_ext_known_pp", "separate",
                     "per_frame_prior", "no_prior", *PRIOR_ABLATIONS, "skeletons3d"),
            paper_peers=True, peers_here=True),
    Section("Ablations", ("shelf", "synthetic", "mhhi", "human36m", "3dhp"),
            ("pcp_avg", "mpjpe_mm", "pa_mpjpe_mm", "accel_error_mm_s2", "pve_mm", "marker_error_mm",
             "marker_error_std_mm"),
            methods=("int_ext", "per_frame_prior", "no_prior", *PRIOR_ABLATIONS, "gt_cameras")),
    Section("Synthetic scenes", ("synthetic",), (*CAMERA_METRICS, *BODY_METRICS, "seconds"), peers_here=True,
            compare=False),
)
"""What :func:`benchmark_markdown` shows, section by section."""

METRIC_LABELS = {
    "focal_error_pct": "focal %", "position_error_mm": "pos. mm", "angle_error_deg": "angle deg",
    "reprojection_error_px": "reproj. px", "pcp_actor1": "A1", "pcp_actor2": "A2", "pcp_actor3": "A3",
    "pcp_avg": "PCP avg", "mpjpe_mm": "MPJPE mm", "pa_mpjpe_mm": "PA-MPJPE mm", "accel_error_mm_s2": "accel mm/s²",
    "pve_mm": "PVE mm", "marker_error_mm": "marker mm", "marker_error_std_mm": "marker std mm", "seconds": "s",
}
"""Short column labels (a metric without one shows its name)."""


def normalise_metrics(table: pd.DataFrame) -> pd.DataFrame:
    """A stored ``metrics`` table with the columns of today's schema: ``view`` (nullable Int32) and
    ``failed_checks`` added empty where it was stored before they existed."""
    table = table.copy()
    if "view" not in table.columns:
        table["view"] = pd.NA
    table["view"] = table["view"].astype("Int32")
    if "failed_checks" not in table.columns:
        table["failed_checks"] = None
    return table[SCHEMAS["metrics"].names]


def benchmark_table(metrics: pd.DataFrame, paper: pd.DataFrame, peers: pd.DataFrame | None = None) -> pd.DataFrame:
    """The long benchmark table (canonical table ``benchmark``): one row per (dataset, sequence, method, metric,
    source).

    Args:
        metrics: our rows (``metrics`` tables of any number of sequences; per-view rows are left out). A figure
            given twice (e.g. by ``metric_tables`` and ``method_tables``) keeps its last occurrence.
        paper: :func:`evaluation.paper_results.paper_results` (a figure given by two tables keeps the first).
        peers: :func:`evaluation.paper_results.peer_results`, or None.
    """
    ours = normalise_metrics(metrics)
    ours = ours[ours["view"].isna()].drop_duplicates(KEY, keep="last")
    parts = [pd.DataFrame({
        **{c: ours[c].to_numpy(dtype=object) for c in KEY},
        "source": ours["method"].map(lambda m: BASELINE_SOURCES.get(m, HUMANCAL)).to_numpy(dtype=object),
        "value": ours["value"].to_numpy(dtype=float),
        "unit": ours["unit"].to_numpy(dtype=object),
        "paper_table": None,
        "failed_checks": ours["failed_checks"].to_numpy(dtype=object),
    })]
    if paper is not None and len(paper):
        published = paper.drop_duplicates(["dataset", "method", "metric"], keep="first")
        parts.append(pd.DataFrame({
            "dataset": published["dataset"].to_numpy(dtype=object), "sequence": None,
            "method": published["method"].to_numpy(dtype=object), "metric": published["metric"].to_numpy(dtype=object),
            "source": PAPER, "value": published["value"].to_numpy(dtype=float),
            "unit": published["unit"].to_numpy(dtype=object), "paper_table": published["table"].to_numpy(dtype=object),
            "failed_checks": None,
        }))
    if peers is not None and len(peers):
        parts.append(pd.DataFrame({
            **{c: peers[c].to_numpy(dtype=object) for c in KEY},
            "source": peers["source"].to_numpy(dtype=object), "value": peers["value"].to_numpy(dtype=float),
            "unit": peers["unit"].to_numpy(dtype=object), "paper_table": None, "failed_checks": None,
        }))
    table = pd.concat([p for p in parts if len(p)], ignore_index=True) if any(len(p) for p in parts) else parts[0]
    table = table.astype({c: object for c in table.columns if c != "value"})
    table = table.sort_values(["dataset", "sequence", "method", "metric", "source"], na_position="first",
                              kind="stable").reset_index(drop=True)
    return validate_table(table[SCHEMAS["benchmark"].names], "benchmark", source="benchmark_table")


def _cell(row: pd.Series | None) -> str:
    """A figure with two decimals (``*``: from cameras that failed a check); blank where there is none."""
    if row is None or pd.isna(row["value"]):
        return ""
    flag = "*" if isinstance(row["failed_checks"], str) and row["failed_checks"] else ""
    return f"{row['value']:.2f}{flag}"


def _render_table(section: Section, dataset: str, sequence: str | None, here: pd.DataFrame,
                  paper: pd.DataFrame) -> str | None:
    """One dataset (and sequence of ours) of a section, or None when it has no figure."""
    here_by = {(r["method"], r["metric"]): r for _, r in here.iterrows()}
    paper_by = {(r["method"], r["metric"]): r for _, r in paper.iterrows()} if section.compare else {}
    ours = set(here.loc[here["source"] == HUMANCAL, "method"])
    declared = list(section.methods) if section.methods is not None else sorted(ours)
    rows = list(declared)
    if section.peers_here or section.methods is None:
        rows += sorted(m for m in set(here.loc[here["source"] != HUMANCAL, "method"]) if m not in rows)
    if section.paper_peers and section.compare:
        rows += [m for m in dict.fromkeys(paper["method"]) if m not in rows]
    rows = [m for m in rows if any((m, k) in here_by or (m, k) in paper_by for k in section.metrics)]
    if not rows:
        return None
    columns: dict[str, list[str]] = {"method": rows}
    sources = {m: r["source"] for (m, _), r in here_by.items()}
    if (section.peers_here or section.methods is None) and sources:
        columns["measured by"] = [sources.get(m, "") for m in rows]
    for metric in section.metrics:
        label = METRIC_LABELS.get(metric, metric)
        mine = [_cell(here_by.get((m, metric))) for m in rows]
        theirs = [_cell(paper_by.get((m, metric))) for m in rows]
        if sequence is not None and any(mine):
            columns[f"{label} here" if section.compare else label] = mine
        if section.compare and any(theirs):
            columns[f"{label} paper"] = theirs
    if len(columns) == 1 + ("measured by" in columns):
        return None
    where = f"{dataset} / {sequence}" if sequence is not None else f"{dataset} (paper only)"
    lines = [f"### {section.title}: {where}", "", _markdown(pd.DataFrame(columns))]
    failed = sorted({r["failed_checks"] for (m, k), r in here_by.items()
                     if m in rows and k in section.metrics and isinstance(r["failed_checks"], str) and r["failed_checks"]})
    if failed:
        lines += ["", f"\\* computed from cameras that failed checks: {'; '.join(failed)}"]
    return "\n".join(lines)


def _markdown(frame: pd.DataFrame) -> str:
    """Pre-formatted cells as a pipe table: names left-aligned, figures right-aligned."""
    align = tuple("left" if c in ("method", "measured by", "asset (seconds)") else "right" for c in frame.columns)
    return frame.to_markdown(index=False, disable_numparse=True, colalign=align)


def benchmark_markdown(table: pd.DataFrame, sections: Sequence[Section] = SECTIONS) -> str:
    """The benchmark table side by side: per section of ``sections``, a table per dataset (and per sequence of
    ours) with the methods as rows and, per metric, the figure measured here and the paper's. Missing figures are
    blank; a figure computed from cameras that failed a check is marked ``*``."""
    out = ["# Benchmark", "",
           "`here`: measured by humancal, or by the baseline / peer tool in `measured by`; `paper`: Huang et al., "
           "TCSVT 2024 (evaluation/paper_results.csv; its regimes: gt_cameras = cameras given, ext = focal known, "
           "int_ext = fully self-calibrated; int_ext_known_pp, not the paper's: int_ext with the true principal points, "
           "a diagnostic; convention_floor, not a fit: the best cameras with centred principal points and one focal "
           "per view, from exact projections of the true joints, below which no self-calibration is expected). "
           "Blank: not measured."]
    for section in sections:
        parts = []
        for dataset in section.datasets:
            rows = table[(table["dataset"] == dataset) & table["metric"].isin(section.metrics)]
            here = rows[rows["source"] != PAPER]
            paper = rows[rows["source"] == PAPER]
            sequences = sorted(here["sequence"].dropna().unique()) or [None]
            for sequence in sequences:
                chunk = here[here["sequence"] == sequence] if sequence is not None else here.iloc[:0]
                rendered = _render_table(section, dataset, sequence, chunk, paper)
                if rendered:
                    parts.append(rendered)
        if parts:
            out += ["", f"## {section.title}", "", "\n\n".join(parts)]
    if len(out) == 3:
        out += ["", "(no figure in any section)"]
    return "\n".join(out) + "\n"


def stage_timings_markdown(timings: pd.DataFrame, paper: pd.DataFrame | None = None) -> str:
    """The ``stage_timings`` table as markdown: one row per asset (in the table's order, ``total`` last), one
    column per sequence (wall seconds of its latest materialization); with ``paper``, the paper's run time of its
    reference workload below."""
    if timings.empty:
        lines = ["(no sequence with a materialized metric_tables)"]
    else:
        order = list(dict.fromkeys(a for a in timings["asset"] if a != "total")) + ["total"]
        wide = timings.pivot_table(index="asset", columns="sequence", values="seconds", aggfunc="first")
        wide = wide.reindex([a for a in order if a in wide.index])
        shown = wide.map(lambda v: "" if pd.isna(v) else f"{v:.1f}")
        lines = [_markdown(shown.reset_index().rename(columns={"asset": "asset (seconds)"})),
                 "", "total: the distinct steps from detections to metric_tables (the method's path; ground-truth "
                     "inputs and method_tables left out)."]
    if paper is not None:
        ref = paper[(paper["dataset"] == "reference_workload") & (paper["metric"] == "seconds")]
        if len(ref):
            parts = "; ".join(f"{r.row}: {r.value:g} s" for r in ref.itertuples())
            lines += ["", f"The paper ({ref['note'].iloc[0].split(';')[0]}): {parts}."]
    return "\n".join(lines) + "\n"
