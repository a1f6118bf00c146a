"""Where sequences come from: the datasets config and the external data root."""

from __future__ import annotations

from pathlib import Path

import dagster as dg

from humancal.datasets.sequences import SequenceSpec, available_sequences, load_datasets_config, parse_partition_key
from humancal.settings import data_root


class DatasetsResource(dg.ConfigurableResource):
    """The datasets config (default: the packaged ``pipelines/datasets.yaml`` or ``$HUMANCAL_DATASETS``)
    and the data root (default: ``$HUMANCAL_DATA_DIR`` or ``../shared/data`` beside the checkout)."""

    config_path: str | None = None
    data_dir: str | None = None

    def root(self) -> Path | None:
        """The data root, or None when there is none on this machine."""
        return Path(self.data_dir) if self.data_dir else data_root()

    def specs(self) -> dict[str, SequenceSpec]:
        return load_datasets_config(Path(self.config_path) if self.config_path else None)

    def spec(self, partition_key: str) -> SequenceSpec:
        """The sequence of a partition key (clear error for an unknown dataset or sequence)."""
        return parse_partition_key(partition_key, self.specs())

    def available(self) -> list[SequenceSpec]:
        """Sequences loadable on this machine (synthetic ones always; others when their data exists)."""
        return available_sequences(self.specs(), self.root())
