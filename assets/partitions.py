"""Partitions: one dynamic partition per sequence, keyed ``<dataset>__<sequence>``.

Keys are registered from the datasets config (``humancal.datasets.sequences``) by the CLI before any run and
by the ``sequence_registry`` asset for users who drive Dagster directly. Defined here, with the assets
it partitions; ``pipelines.partitions`` re-exports it.
"""

import dagster as dg

SEQUENCES = dg.DynamicPartitionsDefinition(name="sequences")
