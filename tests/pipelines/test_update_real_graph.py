"""`humancal update` on the real graph for ``synthetic__tiny`` with the shipped lifter (no external data).

Everything is materialized once, then nothing; a deleted ``extrinsics`` artifact and an ``intrinsics`` file
overwritten with random bytes are each recomputed (alone: they come back identical, so what was computed from
them stands); the on-request ``lifter_trained`` is never trained by an update.
"""

import dagster as dg
import numpy as np
import pytest

from pipelines.definitions import build_definitions
from pipelines.partitions import SEQUENCES
from pipelines.update import update
from resources.datasets import DatasetsResource
from resources.io_managers import partition_path

PARTITION = "synthetic__tiny"
QUIET = {"loggers": {"console": {"config": {"log_level": "WARNING"}}}}

pytestmark = pytest.mark.slow


def test_update_on_the_real_graph(tmp_path):
    storage = str(tmp_path / "artifacts")
    # a data root without any dataset: only what needs no external data can run
    defs = build_definitions(storage, datasets=DatasetsResource(data_dir=str(tmp_path / "no_data")))
    instance = dg.DagsterInstance.ephemeral()
    instance.add_dynamic_partitions(SEQUENCES.name, [PARTITION])

    def run():
        return update(defs, instance, partitions=[PARTITION], run_config=QUIET)

    first = run()
    names = {name for name, _ in first.materialized}
    assert {"lifter_checkpoint", "raw_detections", "detections", "intrinsics", "extrinsics", "metric_tables"} <= names
    assert "lifter_trained" not in names and first.failed == ()
    # the fan-in summaries follow once every registered partition (here the one) is up to date
    assert {"benchmark_table", "stage_timings"} <= names
    assert run().count == 0

    partition_path(storage, "extrinsics", PARTITION).unlink()
    assert run().materialized == (("extrinsics", PARTITION),)

    intrinsics = partition_path(storage, "intrinsics", PARTITION)
    intrinsics.write_bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    assert run().materialized == (("intrinsics", PARTITION),)
    assert run().count == 0
