"""The motion prior assets, run by Dagster on a small synthetic mocap table with a tiny training configuration:
the checkpoint per variant (its data version follows the weights), the held-out metric rows, and the guarantee
that a plain update never trains."""

from __future__ import annotations

import dagster as dg
import numpy as np
import pytest
import roma
import torch

from assets.motion_prior import (
    PRIOR_VARIANT_PARTITIONS,
    PriorEvaluationSettings,
    build_motion_prior_assets,
    prior_from_checkpoint,
)
from humancal.prior import PRIOR_VARIANTS, PriorConfig
from humancal.retarget import RetargetedClip, clips_to_motions_table
from humancal.tables.schemas import validate_table
from pipelines.definitions import build_definitions
from resources.body_model import BodyModelResource
from resources.io_managers import CheckpointIOManagerFactory, ParquetIOManagerFactory, checkpoint_content_version
from resources.torch import TorchResource

EVALUATION = PriorEvaluationSettings(segments=2, frames=10, iterations=2)


def _clip(body, name: str, frames: int, seed: int) -> RetargetedClip:
    g = torch.Generator().manual_seed(seed)
    t = torch.arange(frames, dtype=torch.float64)[:, None, None] / 30.0
    rotvecs = 0.3 * torch.sin(2.0 * np.pi * t + 6.0 * torch.rand(1, 22, 3, generator=g, dtype=torch.float64))
    translation = torch.zeros(frames, 3, dtype=torch.float64)
    translation[:, 2] = 0.95
    rotmats = roma.rotvec_to_rotmat(rotvecs)
    phenotypes = np.full(6, 0.5)
    with torch.no_grad():
        rest = body.rest_skeleton(torch.as_tensor(phenotypes, dtype=body.dtype)[None])
        keypoints = body.keypoints(rest, rotmats[None].to(body.dtype), translation[None].to(body.dtype))[0]
    return RetargetedClip(name=name, subject=name[:2], fps=30.0, phenotypes=phenotypes, bone_rotmats_local=rotmats.numpy(),
                          root_translation_m=translation.numpy(), keypoints_world_m=keypoints.double().numpy(),
                          joints_world_m=None, residual_mm=np.zeros((frames, 0)), mapped_joint_names=(),
                          offsets_m=np.zeros((0, 3)))


@pytest.fixture(scope="module")
def motions(body_model):
    clips = [_clip(body_model, name, 40, i) for i, name in enumerate(("01_01", "01_02", "05_01", "02_01", "14_01"))]
    return clips_to_motions_table(clips)


def _materialize(motions, tmp_path, seed: int, variant: str = "motion_prior",
                 selection=("motion_prior_trained", "prior_metrics")):
    @dg.asset(name="mocap_clips")
    def stub_mocap_clips():
        return motions

    configs = {v: PriorConfig.tiny(v, seed=seed) for v in PRIOR_VARIANTS}
    result = dg.materialize(
        [stub_mocap_clips, *build_motion_prior_assets(configs, EVALUATION)],
        partition_key=variant,
        selection=list(selection),
        resources={
            "io_manager": ParquetIOManagerFactory(base_path=str(tmp_path)),
            "checkpoint_io_manager": CheckpointIOManagerFactory(base_path=str(tmp_path)),
            "body_model": BodyModelResource(),
            "torch_runtime": TorchResource(),
        },
        raise_on_error=True,
        run_config=None,
    )
    events = {e.asset_key.to_user_string(): e for e in result.get_asset_materialization_events()}
    return result, events


@pytest.fixture(scope="module")
def first_run(motions, tmp_path_factory):
    root = tmp_path_factory.mktemp("artifacts")
    motions.to_parquet(root / "mocap_clips.parquet")
    result, events = _materialize(motions, root, seed=0)
    return root, result, events


def test_checkpoint_and_metric_rows(first_run):
    root, result, events = first_run
    checkpoint = result.output_for_node("motion_prior_trained")
    model = prior_from_checkpoint(checkpoint)
    assert model.config.variant == "motion_prior" and model.latent_dim == PriorConfig.tiny().latent_dim
    assert set(checkpoint["val_subjects"]) == {"02", "14"}
    metadata = events["motion_prior_trained"].materialization.metadata
    for key in ("history", "interpolation", "samples"):
        assert "data:image/png;base64," in metadata[key].value
    table = validate_table(result.output_for_node("prior_metrics"), "metrics")
    assert set(table["sequence"]) == {"held_out_02_14"} and set(table["dataset"]) == {"cmu_mocap"}
    assert set(table["method"]) == {"motion_prior", "denoise_prior", "denoise_no_prior"}
    rows = table.set_index(["method", "metric"])["value"]
    for method in ("denoise_prior", "denoise_no_prior"):
        for metric in ("mpjpe_mm", "accel_error_mm_s2", "mpjpe_mm/views_2d", "accel_error_mm_s2/views_2d"):
            assert np.isfinite(rows[(method, metric)]) and rows[(method, metric)] > 0
    assert rows[("motion_prior", "train_seconds")] > 0
    for metric in ("mpjpe_mm", "mpjpe_whole_clip_mm"):  # in the body fit's windows, and whole
        assert np.isfinite(rows[("motion_prior", metric)]) and rows[("motion_prior", metric)] > 0
    assert table.set_index(["method", "metric"]).loc[("motion_prior", "accel_error_mm_s2"), "unit"] == "mm/s^2"


def test_data_version_follows_the_weights(motions, first_run, tmp_path):
    _, result, events = first_run
    first = events["motion_prior_trained"].materialization.tags["dagster/data_version"]
    assert first == checkpoint_content_version(result.output_for_node("motion_prior_trained"))
    motions.to_parquet(tmp_path / "mocap_clips.parquet")
    _, other = _materialize(motions, tmp_path, seed=1, selection=["motion_prior_trained"])
    assert other["motion_prior_trained"].materialization.tags["dagster/data_version"] != first


def test_variant_partitions_and_update_never_trains(tmp_path):
    assert PRIOR_VARIANT_PARTITIONS.get_partition_keys() == list(PRIOR_VARIANTS)
    from assets.common import ON_REQUEST_KEY
    from pipelines.update import stale_asset_partitions

    defs = build_definitions(storage_root=str(tmp_path))
    graph = defs.resolve_asset_graph()
    for name in ("motion_prior_trained", "prior_metrics"):
        assert graph.get(dg.AssetKey(name)).metadata[ON_REQUEST_KEY] == "humancal train prior"
    instance = dg.DagsterInstance.ephemeral()
    instance.add_dynamic_partitions("sequences", ["synthetic__demo"])
    considered = {key.to_user_string() for key, _, _ in stale_asset_partitions(defs, instance, ["synthetic__demo"])}
    assert considered and not considered & {"motion_prior_trained", "prior_metrics", "mocap_clips"}
    with pytest.raises(ValueError, match="one PriorConfig per variant"):
        build_motion_prior_assets({"motion_prior": PriorConfig.tiny()})
