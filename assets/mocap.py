"""Shared by all sequences: CMU mocap retargeted onto the body model."""

import tempfile
from pathlib import Path

import dagster as dg

from assets.common import REQUIRES_DATA_KEY, UPDATE_CONDITION, png_metadata, table_metadata, table_output
from humancal.mocap import identical_files, read_bvh
from humancal.retarget import RetargetConfig, clips_to_motions_table, plot_retarget, pooled_residual_mm, residual_summary, retarget_clips
from resources.body_model import BodyModelResource
from resources.datasets import DatasetsResource

PLOT_CLIP = "02_01"
"""Clip drawn in the metadata picture (a walk)."""


@dg.asset(
    group_name="mocap",
    metadata={**table_metadata("motions"), REQUIRES_DATA_KEY: "cmu_mocap"},
    code_version="1",
    automation_condition=UPDATE_CONDITION,
)
def mocap_clips(context: dg.AssetExecutionContext, body_model: BodyModelResource, datasets: DatasetsResource) -> dg.Output:
    """Every CMU BVH clip of the data root on anny: one shape per subject, 22 bone rotations + root per frame at 30 fps."""
    root = datasets.root()
    folder = None if root is None else root / "cmu_mocap" / "bvh_daz"
    if folder is None or not folder.is_dir():
        raise FileNotFoundError(f"mocap_clips needs cmu_mocap/bvh_daz under the data root (HUMANCAL_DATA_DIR); looked in {folder}")
    paths = sorted(folder.rglob("*.bvh.gz"))
    context.log.info(f"retargeting {len(paths)} clips from {folder}")
    same_takes = identical_files(paths)
    for group in same_takes:
        context.log.warning(
            f"the same take under {len(group)} names: {', '.join(p.name for p in group)}; each is kept, so it counts "
            f"{len(group)} times in its subject's shape fit and in any held-out figure (docs/mocap.md)"
        )

    def progress(done: int, total: int, name: str) -> None:
        if done % 10 == 0 or done == total:
            context.log.info(f"retargeted {done}/{total} clips (last: {name})")

    body = body_model.get()
    clips = retarget_clips(paths, body, RetargetConfig(), progress=progress)
    pooled = pooled_residual_mm(clips)
    summary = residual_summary(clips)
    metadata = {
        "clips": len(clips),
        "frames": int(summary["frames"].sum()),
        "residual_median_mm": pooled["median_mm"],
        "residual_p95_mm": pooled["p95_mm"],
        "identical_files": "; ".join(" = ".join(p.name for p in group) for group in same_takes) or "none",
        "per_clip": dg.MetadataValue.md(summary.to_markdown(index=False, floatfmt=".1f")),
    }
    shown = next((c for c in clips if c.name == PLOT_CLIP), clips[0])
    source = next(p for p in paths if p.name.startswith(shown.name))
    with tempfile.TemporaryDirectory() as tmp:
        png = plot_retarget(read_bvh(source), shown, [0, len(shown.root_translation_m) // 2], Path(tmp) / "retarget.png")
        metadata["picture"] = png_metadata(png, "retarget")
    table = clips_to_motions_table(clips)
    context.log.info(f"residual median {pooled['median_mm']:.1f} mm, p95 {pooled['p95_mm']:.1f} mm over {len(clips)} clips")
    return table_output(table, "motions", **metadata)
