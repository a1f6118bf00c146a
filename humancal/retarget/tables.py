"""Retargeted clips to and from the canonical "motions" table, and residual summaries."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
import torch

from humancal.body import PHENOTYPE_NAMES, BodyModel
from humancal.keypoints import NUM_JOINTS
from humancal.retarget.clips import NUM_POSED_BONES, RetargetedClip
from humancal.tables.schemas import validate_table

__all__ = ["clips_to_motions_table", "motions_table_to_clips", "residual_summary", "pooled_residual_mm"]


def clips_to_motions_table(clips: Sequence[RetargetedClip]) -> pd.DataFrame:
    """The canonical "motions" table (``humancal.tables.schemas``): one row per clip and frame, ``person_id = 0``.

    ``sequence`` is the clip name; ``bone_rotmats_local`` holds the 22 row-major 3x3 matrices (198 values),
    ``keypoints_world_m`` the 23 keypoints (69 values).

    Raises:
        ValueError: no clips, or duplicated clip names.
    """
    clips = list(clips)
    if not clips:
        raise ValueError("clips_to_motions_table: no clips given")
    names = [clip.name for clip in clips]
    duplicated = sorted({n for n in names if names.count(n) > 1})
    if duplicated:
        raise ValueError(f"clips_to_motions_table: clip names must be unique, got duplicates {duplicated}")
    columns: dict[str, list] = {name: [] for name in ("sequence", "person_id", "frame", "bone_rotmats_local",
                                                      "root_translation_m", "phenotypes", "keypoints_world_m")}
    for clip in clips:
        frames = clip.frames
        columns["sequence"] += [clip.name] * frames
        columns["person_id"] += [0] * frames
        columns["frame"] += list(range(frames))
        columns["bone_rotmats_local"] += list(clip.bone_rotmats_local.reshape(frames, -1))
        columns["root_translation_m"] += list(clip.root_translation_m)
        columns["phenotypes"] += [clip.phenotypes] * frames
        columns["keypoints_world_m"] += list(clip.keypoints_world_m.reshape(frames, -1))
    return validate_table(pd.DataFrame(columns), "motions", source="clips_to_motions_table")


def _stack(values: pd.Series, width: int, column: str, sequence: str) -> np.ndarray:
    lengths = {len(v) for v in values}
    if lengths != {width}:
        raise ValueError(f"motions table, sequence {sequence!r}: column {column!r} must hold {width} values per row, "
                         f"got lengths {sorted(lengths)}")
    return np.stack([np.asarray(v, dtype=np.float64) for v in values])


def motions_table_to_clips(
    df: pd.DataFrame, body: BodyModel | None = None, fps: float = 30.0
) -> list[RetargetedClip]:
    """Clips back from a single-person "motions" table (the inverse of :func:`clips_to_motions_table`).

    The table holds no residuals, offsets, subject or frame rate: the clips get empty residuals and offsets, the
    subject from the CMU naming ``<subject>_<trial>`` (the whole name otherwise) and ``fps`` as given. Posed-bone
    heads are recomputed when a body model is given, else ``joints_world_m`` is ``None``.

    Args:
        df: a table that passes ``validate_table(df, "motions")``.
        body: the body model, to recompute ``joints_world_m``.
        fps: the frame rate of the motions.

    Returns:
        One clip per sequence, in order of first appearance.

    Raises:
        ValueError: the table fails its schema, a sequence has several people, frames that are not 0..F-1,
            phenotypes that change within a sequence, or lists of the wrong length.
    """
    table = validate_table(df, "motions", source="motions_table_to_clips")
    clips = []
    for sequence, rows in table.groupby("sequence", sort=False):
        people = sorted(rows["person_id"].unique().tolist())
        if len(people) != 1:
            raise ValueError(
                f"motions_table_to_clips reads single-person tables; sequence {sequence!r} has people {people}"
            )
        rows = rows.sort_values("frame")
        frames = rows["frame"].to_numpy()
        if not np.array_equal(frames, np.arange(len(frames))):
            raise ValueError(f"motions table, sequence {sequence!r}: frames must be 0..{len(frames) - 1} once each")
        rotmats = _stack(rows["bone_rotmats_local"], NUM_POSED_BONES * 9, "bone_rotmats_local", sequence)
        phenotypes = _stack(rows["phenotypes"], len(PHENOTYPE_NAMES), "phenotypes", sequence)
        if not np.allclose(phenotypes, phenotypes[0], rtol=0, atol=1e-12):
            raise ValueError(f"motions table, sequence {sequence!r}: phenotypes change within the sequence")
        translation = _stack(rows["root_translation_m"], 3, "root_translation_m", sequence)
        keypoints = _stack(rows["keypoints_world_m"], NUM_JOINTS * 3, "keypoints_world_m", sequence)
        rotmats = rotmats.reshape(-1, NUM_POSED_BONES, 3, 3)
        joints = None
        if body is not None:
            with torch.no_grad():
                rest = body.rest_skeleton(torch.as_tensor(phenotypes[:1], dtype=body.dtype))
                joints = body.joints(
                    rest,
                    torch.as_tensor(rotmats, dtype=body.dtype)[None],
                    torch.as_tensor(translation, dtype=body.dtype)[None],
                )[0].double().numpy()
        clips.append(
            RetargetedClip(
                name=str(sequence),
                subject=str(sequence).split("_")[0],
                fps=fps,
                phenotypes=phenotypes[0],
                bone_rotmats_local=rotmats,
                root_translation_m=translation,
                keypoints_world_m=keypoints.reshape(-1, NUM_JOINTS, 3),
                joints_world_m=joints,
                residual_mm=np.zeros((len(frames), 0)),
                mapped_joint_names=(),
                offsets_m=np.zeros((0, 3)),
            )
        )
    return clips


def _residuals(clip: RetargetedClip) -> np.ndarray:
    if clip.residual_mm.size == 0:
        raise ValueError(f"clip {clip.name!r} has no residuals (rebuilt from a motions table?)")
    return clip.residual_mm


def residual_summary(clips: Sequence[RetargetedClip]) -> pd.DataFrame:
    """Per clip: frames and the median, 95th percentile and maximum residual over all frames and mapped joints.

    Returns:
        DataFrame with columns ``clip, subject, frames, median_mm, p95_mm, max_mm``, in clip order.

    Raises:
        ValueError: a clip without residuals.
    """
    rows = []
    for clip in clips:
        residual = _residuals(clip)
        rows.append(
            {
                "clip": clip.name,
                "subject": clip.subject,
                "frames": clip.frames,
                "median_mm": float(np.median(residual)),
                "p95_mm": float(np.percentile(residual, 95)),
                "max_mm": float(residual.max()),
            }
        )
    return pd.DataFrame(rows, columns=["clip", "subject", "frames", "median_mm", "p95_mm", "max_mm"])


def pooled_residual_mm(clips: Sequence[RetargetedClip]) -> dict[str, float]:
    """Median, 95th percentile and maximum residual (mm) over every frame and mapped joint of all clips together.

    Raises:
        ValueError: no clips, or a clip without residuals.
    """
    clips = list(clips)
    if not clips:
        raise ValueError("pooled_residual_mm: no clips given")
    pooled = np.concatenate([_residuals(clip).ravel() for clip in clips])
    return {
        "median_mm": float(np.median(pooled)),
        "p95_mm": float(np.percentile(pooled, 95)),
        "max_mm": float(pooled.max()),
    }
