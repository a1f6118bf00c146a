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


def test_a_trained_prior_refits_exactly_the_bodies(tmp_path, body_model):
    """Lineage: the body fit reads ``motion_prior_checkpoint``; training the default variant here (a tiny prior on
    a few synthetic clips, through the graph's own training asset) makes the next update refit the bodies and
    what is computed from them, and nothing upstream."""
    from assets.motion_prior import build_motion_prior_assets
    from humancal.prior import PRIOR_VARIANTS, PriorConfig
    from resources.body_model import BodyModelResource
    from resources.io_managers import CheckpointIOManagerFactory, ParquetIOManagerFactory
    from resources.torch import TorchResource
    from tests.assets.test_motion_prior import EVALUATION, _clip
    from humancal.retarget import clips_to_motions_table

    storage = str(tmp_path / "artifacts")
    datasets = DatasetsResource(data_dir=str(tmp_path / "no_data"))
    instance = dg.DagsterInstance.ephemeral()
    instance.add_dynamic_partitions(SEQUENCES.name, [PARTITION])
    defs = build_definitions(storage, datasets=datasets)
    first = update(defs, instance, partitions=[PARTITION], run_config=QUIET)
    assert ("motion_prior_checkpoint", None) in first.materialized and first.failed == ()
    first_fit = instance.get_latest_materialization_event(dg.AssetKey("fitted_motions")).asset_materialization

    motions = clips_to_motions_table([_clip(body_model, name, 40, i)
                                      for i, name in enumerate(("01_01", "05_01", "02_01", "14_01"))])

    @dg.asset(name="mocap_clips")
    def stub_mocap_clips():
        return motions

    (tmp_path / "mocap").mkdir()
    motions.to_parquet(tmp_path / "mocap" / "mocap_clips.parquet")  # the stub's stored output, read as the input
    configs = {v: PriorConfig.tiny(v, seed=0) for v in PRIOR_VARIANTS}
    dg.materialize([stub_mocap_clips, *build_motion_prior_assets(configs, EVALUATION)], partition_key="motion_prior",
                   selection=["motion_prior_trained"], raise_on_error=True, resources={
                       "io_manager": ParquetIOManagerFactory(base_path=str(tmp_path / "mocap")),
                       "checkpoint_io_manager": CheckpointIOManagerFactory(base_path=storage),
                       "body_model": BodyModelResource(), "torch_runtime": TorchResource()})

    defs = build_definitions(storage, datasets=datasets)  # a new process: the trained prior is now in force
    graph = defs.resolve_asset_graph()
    refit = update(defs, instance, partitions=[PARTITION], run_config=QUIET)
    names = {name for name, _ in refit.materialized}
    descendants, frontier = set(), [dg.AssetKey("motion_prior_checkpoint")]
    while frontier:
        children = graph.get(frontier.pop()).child_keys
        frontier += [key for key in children if key.to_user_string() not in descendants]
        descendants |= {key.to_user_string() for key in children}
    assert {"fitted_motions", "refined_cameras", "method_tables", "metric_tables"} <= descendants
    assert {"motion_prior_checkpoint", "fitted_motions", "refined_cameras", "metric_tables"} <= names
    assert names <= descendants | {"motion_prior_checkpoint"} and refit.failed == ()
    assert "method_tables" not in names  # on request: `humancal benchmark`
    second_fit = instance.get_latest_materialization_event(dg.AssetKey("fitted_motions")).asset_materialization
    assert second_fit.metadata["prior_weights"] != first_fit.metadata["prior_weights"]
    assert update(defs, instance, partitions=[PARTITION], run_config=QUIET).count == 0
