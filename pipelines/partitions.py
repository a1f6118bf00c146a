"""Partitions: one dynamic partition per sequence, keyed ``<dataset>__<sequence>``.

Keys are registered from the datasets config (``humancal.sequences``) by the CLI before any run and
by the ``sequence_registry`` asset for users who drive Dagster directly.
"""

import dagster as dg

SEQUENCES = dg.DynamicPartitionsDefinition(name="sequences")
