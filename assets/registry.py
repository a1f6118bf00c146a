"""The sequence registry: turns the datasets config into dynamic partitions."""


import dagster as dg
import pandas as pd

from assets.partitions import SEQUENCES
from resources.datasets import DatasetsResource


@dg.asset(group_name="registry", code_version="1")
def sequence_registry(context: dg.AssetExecutionContext, datasets: DatasetsResource) -> dg.MaterializeResult:
    """Register every sequence of the datasets config that can be loaded here as a partition.

    Synthetic sequences are always registered; real ones when their folder exists under the data root.
    Materialize this once before materializing partitions with the plain Dagster CLI.
    """
    keys = [spec.key for spec in datasets.available()]
    existing = set(context.instance.get_dynamic_partitions(SEQUENCES.name))
    new = [k for k in keys if k not in existing]
    if new:
        context.instance.add_dynamic_partitions(SEQUENCES.name, new)
    table = pd.DataFrame({"partition": keys, "new": [k in new for k in keys]})
    return dg.MaterializeResult(
        metadata={"sequences": dg.MetadataValue.md(table.to_markdown(index=False)), "registered": len(keys), "new": len(new)}
    )
