"""What every humancal asset shares: the automation condition, content data versions, table metadata."""


import base64
import warnings
from pathlib import Path

import dagster as dg
import pandas as pd

from assets.partitions import SEQUENCES
from resources.io_managers import TABLE_METADATA_KEY, table_content_version

AC = dg.AutomationCondition

UPDATE_CONDITION = (
    (AC.missing() | (AC.any_deps_match(AC.data_version_changed()) | AC.code_version_changed()).since_last_handled())
    & ~AC.any_deps_missing()
    & ~AC.any_deps_in_progress()
    & ~AC.in_progress()
).with_label("missing, code changed, or upstream data changed")
"""When ``humancal update`` (or the automation sensor) recomputes an asset partition: it was never
materialized, its code_version changed, or an upstream asset produced different data."""


ON_REQUEST_KEY = "humancal/on_request"
"""Asset metadata marking an asset that ``humancal update`` never computes on its own (e.g. ``lifter_trained``:
fifteen minutes of training); the value names the command that does."""

REQUIRES_DATA_KEY = "humancal/requires_data"
"""Asset metadata naming the data-root folder an unpartitioned asset reads (e.g. ``cmu_mocap``)."""


def table_metadata(name: str) -> dict[str, str]:
    """Asset metadata declaring that an asset holds canonical table ``name``."""
    return {TABLE_METADATA_KEY: name}


def sequence_asset(table: str, code_version: str, **kwargs):
    """``@dg.asset`` for a per-sequence table: partitioned by sequence, group ``sequence``, the update condition."""
    return dg.asset(
        partitions_def=SEQUENCES,
        group_name="sequence",
        metadata=table_metadata(table),
        code_version=code_version,
        automation_condition=UPDATE_CONDITION,
        **kwargs,
    )


def table_data_version(df: pd.DataFrame, name: str) -> dg.DataVersion:
    """Content hash of a canonical table (so identical outputs do not trigger downstream work).

    ``humancal update`` recomputes the same hash from the stored file to notice a damaged artifact
    (:func:`resources.io_managers.table_content_version` is the one definition).
    """
    return dg.DataVersion(table_content_version(df, name))


def versioned_output(value, data_version: str, output_name: str = "result", **metadata) -> dg.Output:
    """An Output carrying the given data version (a content digest) and metadata."""
    with warnings.catch_warnings():
        # Output(data_version=...) is marked beta; the pinned dagster version is what we test against.
        warnings.simplefilter("ignore", dg.BetaWarning)
        return dg.Output(value, output_name=output_name, data_version=dg.DataVersion(data_version), metadata=metadata)


def table_output(df: pd.DataFrame, name: str, output_name: str = "result", **metadata) -> dg.Output:
    """An Output carrying a content data version and summary metadata."""
    return versioned_output(df, table_data_version(df, name).value, output_name, **metadata)


def png_metadata(path: Path, alt: str) -> dg.MetadataValue:
    """A PNG file as Markdown metadata (an inline image the Dagster UI shows on the asset page)."""
    data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
    return dg.MetadataValue.md(f"![{alt}](data:image/png;base64,{data})")
