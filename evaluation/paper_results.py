"""The published numbers of the paper this project implements, and the peer figures measured here by hand.

``paper_results.csv`` (next to this module) holds every number of Huang et al., "Simultaneously Recovering
Multi-Person Meshes and Multi-View Cameras with Human Semantics" (IEEE TCSVT 2024; ``shared/paper/
000_6ebbf50d55d75e97.txt``) that a humancal metric can be compared with:

========== ============================================================ ==========================================
table      what                                                         datasets / metrics
========== ============================================================ ==========================================
Table I    PCP of multi-person 3D pose methods (its own and 12 peers)    campus, shelf: ``pcp_actor1..3``
Table II   marker-to-vertex distance by number of views                  mhhi: ``marker_error_mm/views_N``
Table III  single-person figures                                         human36m, 3dhp: ``pa_mpjpe_mm``,
                                                                         ``mpjpe_mm``, ``accel_error_mm_s2``
Table IV   initial focal length error per camera                         vptz: ``focal_error_pct/<camera>``
Table V    estimated cameras per regime                                  panoptic, shelf: ``focal_error_pct``,
                                                                         ``position_error_mm``, ``angle_error_deg``,
                                                                         ``reprojection_error_px``
Table VI   ablation of association and prior, per camera regime          mhhi ``marker_error_mm`` (+ ``_std_mm``),
                                                                         campus/shelf PCP, ocmotion MPJPE/PA/PVE
Table VII  ablation of the motion prior's components                     mhhi: ``marker_error_mm`` (+ ``_std_mm``)
Table VIII association precision                                         mvmhat: ``aidp_pct``
Sec. IV-B  run time of the reference workload (30 s, 5 views, 4 people)  reference_workload: ``seconds``
========== ============================================================ ==========================================

The paper's regimes map onto our method names: "Ours" with the cameras given -> ``gt_cameras``; "+ext." (focal
known, extrinsics refined) -> ``ext``; "+int +ext." (fully self-calibrated) -> ``int_ext``; "Initial ours" ->
``init``; "Separate ours" -> ``separate``; "VPoser-t +int +ext." (its per-frame pose prior baseline) ->
``per_frame_prior``; the prior ablations "w/o local linear", "w/ basic GRU", "w/o skip-connection" ->
``no_local_linear``, ``basic_gru``, ``no_skip`` (the paper ran those with the cameras given; ours run as
``int_ext``: the ``note`` column says so). Other works get a peer name (``dmmr``, ``vposer_t``, ``mvpose``,
``photoscan``, ...; with ``_ext`` / ``_int_ext`` for their regimes).

The paper prints the three Shelf/Campus actors only; :func:`paper_results` adds their mean as ``pcp_avg`` (note
``derived: ...``), the figure other works quote (98.1 with the ground-truth cameras, 93.8 fully self-calibrated on
Shelf).

``peer_results.csv`` holds figures of other tools measured here outside the graph (Pose2Sim on Shelf, from the
design notes, ``shared/DESIGN.md`` section 8).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

__all__ = ["PAPER_COLUMNS", "PEER_COLUMNS", "paper_results", "peer_results"]

PAPER_FILE = Path(__file__).with_name("paper_results.csv")
PEER_FILE = Path(__file__).with_name("peer_results.csv")

PAPER_COLUMNS = ("table", "label", "row", "method", "dataset", "metric", "value", "unit", "note")
"""The columns of the paper's numbers, in order."""

PEER_COLUMNS = ("dataset", "sequence", "method", "metric", "value", "unit", "source", "note")
"""The columns of the peer figures measured here, in order (``source``: the peer tool, e.g. ``pose2sim``)."""

PCP_ACTORS = ("pcp_actor1", "pcp_actor2", "pcp_actor3")
DERIVED_AVERAGE_NOTE = "derived: mean of pcp_actor1-3 (the paper lists the actors only)"


def _read(path: Path, columns: tuple[str, ...]) -> pd.DataFrame:
    table = pd.read_csv(path, comment="#", dtype=str, keep_default_na=False)
    if tuple(table.columns) != columns:
        raise ValueError(f"{path}: columns must be {list(columns)}, got {list(table.columns)}")
    values = pd.to_numeric(table["value"], errors="coerce")
    bad = table.loc[~np.isfinite(values), "value"]
    if len(bad):
        raise ValueError(f"{path}: value must be a finite number, got {bad.iloc[0]!r} (leave out empty cells)")
    required = [c for c in columns if c not in ("note", "sequence")]
    for column in required:
        if (table[column].str.strip() == "").any():
            raise ValueError(f"{path}: column {column!r} has empty cells")
    return table.assign(value=values.astype(float))


def paper_results(path: str | Path | None = None) -> pd.DataFrame:
    """The paper's numbers (columns :data:`PAPER_COLUMNS`), with the derived Shelf/Campus PCP averages.

    Raises:
        ValueError: wrong columns, a value that is not a finite number, an empty required cell, the same cell twice,
            or one (dataset, method, metric) given two different values by two tables.
    """
    path = Path(path) if path is not None else PAPER_FILE
    table = _read(path, PAPER_COLUMNS)
    twice = table.duplicated(["table", "row", "dataset", "metric"], keep=False)
    if twice.any():
        first = table[twice].iloc[0]
        raise ValueError(f"{path}: {first['table']} row {first['row']!r} gives {first['dataset']} {first['metric']} twice")
    spread = table.groupby(["dataset", "method", "metric"])["value"].agg(lambda v: v.max() - v.min())
    if (spread > 1e-9).any():
        dataset, method, metric = spread[spread > 1e-9].index[0]
        raise ValueError(f"{path}: {method} {dataset} {metric} differs between tables")
    return pd.concat([table, _pcp_averages(table)], ignore_index=True)


def _pcp_averages(table: pd.DataFrame) -> pd.DataFrame:
    actors = table[table["metric"].isin(PCP_ACTORS)]
    rows = []
    for (tab, row, dataset), group in actors.groupby(["table", "row", "dataset"], sort=False):
        if set(group["metric"]) == set(PCP_ACTORS):
            first = group.iloc[0]
            rows.append({**first.to_dict(), "metric": "pcp_avg", "value": round(float(group["value"].mean()), 2),
                         "note": "; ".join(n for n in (first["note"], DERIVED_AVERAGE_NOTE) if n)})
    return pd.DataFrame(rows, columns=list(PAPER_COLUMNS))


def peer_results(path: str | Path | None = None) -> pd.DataFrame:
    """Figures of peer tools measured here by hand (columns :data:`PEER_COLUMNS`; ``sequence`` as in our tables).

    Raises:
        ValueError: wrong columns, a value that is not a finite number, or an empty required cell.
    """
    path = Path(path) if path is not None else PEER_FILE
    return _read(path, PEER_COLUMNS)
