"""Canonical tables: one declared pyarrow schema each, and their validation.

Every artifact that moves between stages is one of these tables (long format, one row per
joint where joints are involved), held in memory as a ``pandas.DataFrame`` and stored as Parquet.
Conventions (frames, units, rotation formats) are those of ``docs/conventions.md``; units are in
the column names.

Tables:
    detections:   2D keypoints of detected people, one row per (frame, view, det_id, joint).
    lifted_detections: detections with the lifter's 3D pose of each, one row per (frame, view, det_id, joint)
                  for all 23 joints (x_px/y_px NaN and score 0 where the joint was not detected).
    intrinsics:   one row per view: the initial intrinsics from upright people, with diagnostics.
    views:        one row per view: name and image size (what a user knows without calibration).
    poses3d:      3D keypoints of people in the world frame, one row per (frame, person_id, joint).
    skeletons3d:  the people's 3D joints triangulated by the association, one row per (frame, person_id, joint);
                  ``num_views`` views triangulated the joint in that frame (0 with ``valid`` True: filled from
                  the person's neighbouring frames; 0, NaN coordinates and ``valid`` False: missing).
    cameras:      one row per view: pinhole intrinsics, world-to-camera extrinsics, image size.
    associations: person id of each detection (-1 = not a person / not associated).
    people:       per person body-model shape (anny phenotypes) and height.
    motions:      per person and frame body-model parameters (later stages write them).
    metrics:      evaluation figures (dataset, sequence, method, metric, view, value, unit, failed_checks); ``view``
                  is null for a figure that is not per view; ``failed_checks`` names the checks that the estimated
                  cameras a figure was computed from failed (comma-separated; empty: they passed every check; null:
                  not computed from estimated cameras).
    benchmark:    every sequence's headline figures beside the paper's and the peers' (dataset, sequence, method,
                  metric, source, value, unit, paper_table, failed_checks); ``source`` is ``humancal``, ``paper`` or
                  the peer measured here; ``sequence`` is null for the paper's figures (per dataset);
                  ``paper_table`` names the paper's table (null for figures measured here).
    stage_timings: wall seconds of the latest materialization of each per-sequence asset (sequence = the partition
                  key, asset, step, seconds, run_id, materialized_at); asset ``total`` sums the distinct steps from
                  ``detections`` to ``metric_tables`` (run_id, materialized_at null).
    run_records:  what the latest runs recorded of a sequence's stages, one row per asset (sequence, asset,
                  seconds, run_id, failed_checks): ``seconds`` its ``seconds_total`` metadata (null: unrecorded),
                  ``failed_checks`` the checks its cameras failed (comma-separated; empty: none; ``unchecked``:
                  never recorded; null for assets without camera checks).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow as pa

__all__ = [
    "SCHEMAS",
    "NULLABLE_COLUMNS",
    "TableError",
    "validate_table",
    "check_values",
    "empty_table",
    "to_arrow",
    "table_to_pandas",
]


class TableError(ValueError):
    """A table does not match its declared schema; the message names table, column and expectation."""


_DETECTION_FIELDS = [
    ("sequence", pa.string()),
    ("frame", pa.int32()),
    ("view", pa.int32()),
    ("det_id", pa.int32()),
    ("joint", pa.string()),
    ("x_px", pa.float64()),
    ("y_px", pa.float64()),
    ("score", pa.float64()),
]
"""The columns of a detected keypoint, which ``lifted_detections`` extends."""

SCHEMAS: dict[str, pa.Schema] = {
    "detections": pa.schema(_DETECTION_FIELDS),
    "lifted_detections": pa.schema(
        _DETECTION_FIELDS + [
            ("x_crop_m", pa.float64()),
            ("y_crop_m", pa.float64()),
            ("z_crop_m", pa.float64()),
            ("box_cx_px", pa.float64()),
            ("box_cy_px", pa.float64()),
            ("height_m", pa.float64()),
            ("upright_score", pa.float64()),
            ("lifted", pa.bool_()),
        ]
    ),
    "intrinsics": pa.schema(
        [
            ("sequence", pa.string()),
            ("view", pa.int32()),
            ("fx_px", pa.float64()),
            ("fy_px", pa.float64()),
            ("cx_px", pa.float64()),
            ("cy_px", pa.float64()),
            ("width_px", pa.int32()),
            ("height_px", pa.int32()),
            ("status", pa.string()),
            ("focal_rel_uncertainty", pa.float64()),
            ("num_candidates", pa.int32()),
            ("num_inliers", pa.int32()),
            ("vanishing_x_px", pa.float64()),
            ("vanishing_y_px", pa.float64()),
            ("up_x", pa.float64()),
            ("up_y", pa.float64()),
            ("up_z", pa.float64()),
            ("tilt_deg", pa.float64()),
            ("roll_deg", pa.float64()),
            ("camera_height_m", pa.float64()),
            ("vp_rms_px", pa.float64()),
            ("rms_px", pa.float64()),
        ]
    ),
    "views": pa.schema(
        [
            ("sequence", pa.string()),
            ("view", pa.int32()),
            ("name", pa.string()),
            ("width_px", pa.int32()),
            ("height_px", pa.int32()),
        ]
    ),
    "poses3d": pa.schema(
        [
            ("sequence", pa.string()),
            ("frame", pa.int32()),
            ("person_id", pa.int32()),
            ("joint", pa.string()),
            ("x_m", pa.float64()),
            ("y_m", pa.float64()),
            ("z_m", pa.float64()),
            ("valid", pa.bool_()),
        ]
    ),
    "cameras": pa.schema(
        [
            ("sequence", pa.string()),
            ("view", pa.int32()),
            ("fx_px", pa.float64()),
            ("fy_px", pa.float64()),
            ("cx_px", pa.float64()),
            ("cy_px", pa.float64()),
            ("R_cam_from_world", pa.list_(pa.float64(), 9)),
            ("t_cam_from_world_m", pa.list_(pa.float64(), 3)),
            ("distortion", pa.list_(pa.float64(), 5)),
            ("width_px", pa.int32()),
            ("height_px", pa.int32()),
        ]
    ),
    "associations": pa.schema(
        [
            ("sequence", pa.string()),
            ("frame", pa.int32()),
            ("view", pa.int32()),
            ("det_id", pa.int32()),
            ("person_id", pa.int32()),
        ]
    ),
    "people": pa.schema(
        [
            ("sequence", pa.string()),
            ("person_id", pa.int32()),
            ("gender", pa.float64()),
            ("age", pa.float64()),
            ("muscle", pa.float64()),
            ("weight", pa.float64()),
            ("height", pa.float64()),
            ("proportions", pa.float64()),
            ("height_m", pa.float64()),
        ]
    ),
    "motions": pa.schema(
        [
            ("sequence", pa.string()),
            ("person_id", pa.int32()),
            ("frame", pa.int32()),
            ("bone_rotmats_local", pa.list_(pa.float64())),
            ("root_translation_m", pa.list_(pa.float64(), 3)),
            ("phenotypes", pa.list_(pa.float64())),
            ("keypoints_world_m", pa.list_(pa.float64())),
        ]
    ),
    "metrics": pa.schema(
        [
            ("dataset", pa.string()),
            ("sequence", pa.string()),
            ("method", pa.string()),
            ("metric", pa.string()),
            ("view", pa.int32()),
            ("value", pa.float64()),
            ("unit", pa.string()),
            ("failed_checks", pa.string()),
        ]
    ),
    "benchmark": pa.schema(
        [
            ("dataset", pa.string()),
            ("sequence", pa.string()),
            ("method", pa.string()),
            ("metric", pa.string()),
            ("source", pa.string()),
            ("value", pa.float64()),
            ("unit", pa.string()),
            ("paper_table", pa.string()),
            ("failed_checks", pa.string()),
        ]
    ),
    "stage_timings": pa.schema(
        [
            ("sequence", pa.string()),
            ("asset", pa.string()),
            ("step", pa.string()),
            ("seconds", pa.float64()),
            ("run_id", pa.string()),
            ("materialized_at", pa.timestamp("us", tz="UTC")),
        ]
    ),
    "run_records": pa.schema(
        [
            ("sequence", pa.string()),
            ("asset", pa.string()),
            ("seconds", pa.float64()),
            ("run_id", pa.string()),
            ("failed_checks", pa.string()),
        ]
    ),
}
"""The declared schema of every canonical table, by table name."""

# the 3D skeletons of the association: the columns of poses3d plus the views that triangulated each joint
SCHEMAS["skeletons3d"] = SCHEMAS["poses3d"].insert(SCHEMAS["poses3d"].get_field_index("valid"),
                                                   pa.field("num_views", pa.int32()))

NULLABLE_COLUMNS: dict[str, frozenset[str]] = {
    "metrics": frozenset({"view", "failed_checks"}),
    "benchmark": frozenset({"sequence", "paper_table", "failed_checks"}),
    "stage_timings": frozenset({"run_id", "materialized_at"}),
    "run_records": frozenset({"seconds", "run_id", "failed_checks"}),
}
"""Columns that may hold nulls (every other column of every table must be filled), by table name. In pandas a
nullable integer column is a nullable ``Int32`` column (``pd.NA`` for null)."""

_NON_NEGATIVE_INT = {"frame", "view", "det_id"}


def empty_table(name: str) -> pd.DataFrame:
    """An empty DataFrame with the columns and dtypes of table ``name``."""
    return SCHEMAS[_known(name)].empty_table().to_pandas()


def to_arrow(df: pd.DataFrame, name: str, *, source: str = "") -> pa.Table:
    """Convert ``df`` to a pyarrow Table with exactly the declared schema of ``name``.

    Extra columns are an error (they would be silently dropped otherwise); missing columns,
    uncastable values and NaN in integer columns raise :class:`TableError`.
    """
    schema = SCHEMAS[_known(name)]
    where = f" ({source})" if source else ""
    missing = [f.name for f in schema if f.name not in df.columns]
    if missing:
        raise TableError(f"table '{name}'{where}: missing column(s) {missing}; expected columns {schema.names}")
    extra = [c for c in df.columns if c not in schema.names]
    if extra:
        raise TableError(f"table '{name}'{where}: unexpected column(s) {extra}; expected columns {schema.names}")
    arrays = []
    for field in schema:
        col = df[field.name]
        try:
            if pa.types.is_fixed_size_list(field.type) or pa.types.is_list(field.type):
                values = [None if v is None else np.asarray(v, dtype=np.float64).ravel().tolist() for v in col]
                arr = pa.array(values, type=field.type)
            else:
                # Floats keep NaN (a coordinate may be NaN where the table allows); elsewhere a
                # pandas missing value (None/NaN/NA) becomes a null, reported below.
                floating = pa.types.is_floating(field.type)
                arr = pa.array(col.to_numpy() if floating else col, type=field.type, from_pandas=not floating)
        except (pa.ArrowInvalid, pa.ArrowTypeError, TypeError, ValueError) as err:
            raise TableError(
                f"table '{name}'{where}: column '{field.name}' cannot be stored as {field.type}: {err}"
            ) from None
        if arr.null_count and field.name not in NULLABLE_COLUMNS.get(name, ()):
            raise TableError(f"table '{name}'{where}: column '{field.name}' has {arr.null_count} missing value(s)")
        arrays.append(arr)
    return pa.Table.from_arrays(arrays, schema=schema)


def validate_table(df: pd.DataFrame, name: str, *, source: str = "") -> pd.DataFrame:
    """Check ``df`` against table ``name`` and return it with the declared dtypes.

    Beyond the schema (see :func:`check_values`): identifiers non-negative, required values finite,
    scores in [0, 1].

    Raises:
        TableError: naming the table, the column and what was expected.
    """
    table = to_arrow(df, name, source=source)
    check_values(table, name, source=source)
    return table_to_pandas(table, name)


def table_to_pandas(table: pa.Table, name: str) -> pd.DataFrame:
    """A stored canonical table as pandas, its nullable integer columns as pandas nullable integers (not float)."""
    df = table.to_pandas()
    for col in NULLABLE_COLUMNS.get(_known(name), ()):
        field = table.schema.field(col)
        if pa.types.is_integer(field.type):
            df[col] = df[col].astype(f"Int{field.type.bit_width}")
    return df


def check_values(table: pa.Table, name: str, *, source: str = "") -> None:
    """Value rules the schema cannot express: frame/view/det_id >= 0; detections x/y/score and camera
    intrinsics finite; detection scores in [0, 1].

    Raises:
        TableError: naming the table, the column and what was expected.
    """
    where = f" ({source})" if source else ""
    for col in sorted(_NON_NEGATIVE_INT & set(table.column_names)):
        values = table.column(col).drop_null().to_numpy()
        if len(values) and (values < 0).any():
            raise TableError(f"table '{name}'{where}: column '{col}' must be >= 0, got {int(values.min())}")
    finite_cols = {
        "detections": ["x_px", "y_px", "score"],
        "cameras": ["fx_px", "fy_px", "cx_px", "cy_px"],
    }.get(name, [])
    for col in finite_cols:
        bad = ~np.isfinite(table.column(col).to_numpy())
        if bad.any():
            raise TableError(f"table '{name}'{where}: column '{col}' has {int(bad.sum())} non-finite value(s)")
    if name in ("detections", "lifted_detections") and table.num_rows:
        s = table.column("score").to_numpy()
        if (s < 0).any() or (s > 1).any():
            raise TableError(f"table '{name}'{where}: column 'score' must lie in [0, 1]")


def _known(name: str) -> str:
    if name not in SCHEMAS:
        raise TableError(f"unknown table '{name}'; known tables are {sorted(SCHEMAS)}")
    return name
