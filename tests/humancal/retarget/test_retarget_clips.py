"""The public retarget API on a synthetic clip made by the body model: shape and poses come back, tables round-trip."""

import dataclasses

import numpy as np
import pandas as pd
import pytest
import torch

from humancal.mocap import MocapClip
from humancal.retarget import (
    RetargetConfig,
    RetargetedClip,
    SubjectFit,
    clips_to_motions_table,
    fit_subject,
    fit_subject_phenotypes,
    motions_table_to_clips,
    plot_retarget,
    pooled_residual_mm,
    residual_summary,
    retarget_clip,
    retarget_clips,
)
from humancal.tables.schemas import validate_table


def _segment_lengths_m(body_model, phenotypes):
    """Thigh, shin, upper arm, forearm, pelvis-to-neck lengths of the rest skeleton."""
    rest = body_model.rest_skeleton(torch.as_tensor(phenotypes, dtype=torch.float32)[None])
    heads = rest.bone_heads_m[0]
    index = body_model.posed_bones.index
    pairs = [("upperleg01.L", "lowerleg01.L"), ("lowerleg01.L", "foot.L"), ("upperarm01.L", "lowerarm01.L"),
             ("lowerarm01.L", "wrist.L"), ("root", "neck01")]
    return np.array([float((heads[index(a)] - heads[index(b)]).norm()) for a, b in pairs])


@pytest.fixture(scope="module")
def subject_fit(body_model, synthetic_clip):
    clip, _ = synthetic_clip
    return fit_subject(clip, body_model, RetargetConfig.tiny())


def test_shape_fit_recovers_the_bone_lengths_of_a_known_body(body_model, synthetic_clip, subject_fit):
    clip, truth = synthetic_clip
    start = _segment_lengths_m(body_model, np.array(RetargetConfig().phenotype_init))
    fitted = _segment_lengths_m(body_model, subject_fit.phenotypes)
    true = _segment_lengths_m(body_model, truth["phenotypes"])
    # Shin, forearm and pelvis-to-neck are pinned by offset-free joints (or lengths along the spine): within
    # 3 mm, from a start 5-20 mm off. Thigh and upper arm end at joints with learned offsets (hip, shoulder),
    # which can trade a centimetre of length: within 1.5 cm.
    pinned = [1, 3, 4]
    assert np.abs(start - true)[pinned].max() > 0.005
    np.testing.assert_allclose(fitted[pinned], true[pinned], atol=0.003)
    np.testing.assert_allclose(fitted, true, atol=0.015)
    assert subject_fit.residual_mm < 1.0
    assert subject_fit.subject == "91" and subject_fit.frames_used == 24
    assert subject_fit.offsets_m.shape == (len(subject_fit.mapped_joint_names), 3)
    assert np.all((subject_fit.phenotypes >= 0) & (subject_fit.phenotypes <= 1))


def test_retarget_clip_reproduces_the_synthetic_body(body_model, synthetic_clip, subject_fit):
    clip, truth = synthetic_clip
    result = retarget_clip(clip, body_model, subject_fit, RetargetConfig.tiny())
    assert isinstance(result, RetargetedClip)
    assert (result.name, result.subject, result.fps, result.frames) == ("91_01", "91", 30.0, clip.frames)
    assert result.bone_rotmats_local.shape == (clip.frames, 22, 3, 3)
    assert result.joints_world_m.shape == (clip.frames, 22, 3)
    assert result.residual_mm.shape == (clip.frames, len(result.mapped_joint_names))
    assert np.median(result.residual_mm) < 2.0 and np.percentile(result.residual_mm, 95) < 6.0
    # The keypoints of the retargeted body are those of the true body (up to the shape and twist freedom).
    keypoint_error_mm = np.linalg.norm(result.keypoints_world_m - truth["keypoints"], axis=-1) * 1000
    assert np.median(keypoint_error_mm) < 15.0
    rotations = result.bone_rotmats_local
    np.testing.assert_allclose(rotations @ np.swapaxes(rotations, -1, -2), np.broadcast_to(np.eye(3), rotations.shape),
                               atol=1e-5)
    assert not result.bone_rotmats_local.flags.writeable


def test_retarget_clip_with_phenotypes_only_fits_the_offsets(body_model, synthetic_clip):
    clip, truth = synthetic_clip
    result = retarget_clip(clip, body_model, truth["phenotypes"], RetargetConfig.tiny())
    np.testing.assert_array_equal(result.phenotypes, truth["phenotypes"])
    assert np.median(result.residual_mm) < 2.0
    assert np.any(result.offsets_m != 0)


def test_clips_are_resampled_and_grouped_by_subject(body_model, synthetic_clip, make_clip):
    clip, _ = synthetic_clip
    fast = clip.resample(60.0)  # 60 fps in, 30 fps out
    other = make_clip(20, "92_01", seed=5)[0]
    calls = []
    results = retarget_clips([fast, other], body_model, RetargetConfig.tiny(),
                             progress=lambda done, total, name: calls.append((done, total, name)))
    assert [r.name for r in results] == ["91_01", "92_01"]
    assert results[0].fps == 30.0 and results[0].frames == clip.frames
    assert calls == [(1, 2, "91_01"), (2, 2, "92_01")]
    with pytest.raises(ValueError, match="unique"):
        retarget_clips([clip, clip], body_model, RetargetConfig.tiny())
    with pytest.raises(ValueError, match="BVH"):
        retarget_clips(["walk.amc"], body_model, RetargetConfig.tiny())


def test_bad_inputs_raise_clear_errors(body_model, synthetic_clip, subject_fit, make_clip):
    clip, _ = synthetic_clip
    keep = [n for n in clip.joint_names if n != "lFoot_end"]
    lacking = MocapClip(clip.name, clip.subject, keep, (-1,) * len(keep),
                        clip.positions_world_m[:, [clip.joint_index(n) for n in keep]], clip.fps)
    with pytest.raises(ValueError, match=r"lacks the mapped mocap joint\(s\) \['lFoot_end'\]"):
        retarget_clip(lacking, body_model, subject_fit, RetargetConfig.tiny())
    with pytest.raises(ValueError, match=r"lacks the mapped mocap joint"):
        fit_subject_phenotypes(lacking, body_model, RetargetConfig.tiny())
    with pytest.raises(ValueError, match="non-finite"):
        broken = clip.positions_world_m.copy()
        broken[3, 2, 0] = np.nan
        MocapClip(clip.name, clip.subject, clip.joint_names, clip.parents, broken, clip.fps)
    nan_clip = MocapClip(clip.name, clip.subject, clip.joint_names, clip.parents, clip.positions_world_m, clip.fps)
    broken = nan_clip.positions_world_m.copy()
    broken[3, 2, 0] = np.nan
    object.__setattr__(nan_clip, "positions_world_m", broken)  # past MocapClip's own check
    with pytest.raises(ValueError, match="non-finite"):
        retarget_clip(nan_clip, body_model, subject_fit, RetargetConfig.tiny())
    with pytest.raises(ValueError, match=r"within \[0, 1\]"):
        retarget_clip(clip, body_model, np.array([0.5, 0.5, 0.5, 0.5, 1.5, 0.5]), RetargetConfig.tiny())
    with pytest.raises(ValueError, match="shape \\(6,\\)"):
        retarget_clip(clip, body_model, np.zeros(5), RetargetConfig.tiny())
    other_table = dataclasses.replace(RetargetConfig.tiny(), links=RetargetConfig.tiny().links[:-2])
    with pytest.raises(ValueError, match="made for the mapped joints"):
        retarget_clip(clip, body_model, subject_fit, other_table)
    with pytest.raises(ValueError, match="one subject"):
        fit_subject([clip, make_clip(10, "93_01")[0]], body_model, RetargetConfig.tiny())
    with pytest.raises(ValueError, match="no clips"):
        fit_subject([], body_model)


@pytest.fixture(scope="module")
def retargeted(body_model, synthetic_clip, subject_fit):
    return retarget_clip(synthetic_clip[0], body_model, subject_fit, RetargetConfig.tiny())


def test_motions_table_round_trip(body_model, retargeted):
    table = clips_to_motions_table([retargeted])
    validate_table(table, "motions")
    assert len(table) == retargeted.frames
    assert set(table["sequence"]) == {"91_01"} and set(table["person_id"]) == {0}
    back = motions_table_to_clips(table, body_model)
    assert len(back) == 1
    clip = back[0]
    assert (clip.name, clip.subject, clip.frames) == ("91_01", "91", retargeted.frames)
    np.testing.assert_array_equal(clip.bone_rotmats_local, retargeted.bone_rotmats_local)
    np.testing.assert_array_equal(clip.keypoints_world_m, retargeted.keypoints_world_m)
    np.testing.assert_array_equal(clip.phenotypes, retargeted.phenotypes)
    np.testing.assert_allclose(clip.joints_world_m, retargeted.joints_world_m, atol=1e-6)
    assert clip.residual_mm.shape == (retargeted.frames, 0)
    assert motions_table_to_clips(table)[0].joints_world_m is None
    with pytest.raises(ValueError, match="no residuals"):
        residual_summary(back)


def test_motions_table_rejects_bad_rows(retargeted):
    table = clips_to_motions_table([retargeted])
    two_people = pd.concat([table, table.assign(person_id=1)], ignore_index=True)
    with pytest.raises(ValueError, match="single-person"):
        motions_table_to_clips(two_people)
    with pytest.raises(ValueError, match="frames must be"):
        motions_table_to_clips(table.iloc[1:])
    changed = table.copy()
    changed.at[2, "phenotypes"] = np.full(6, 0.1)
    with pytest.raises(ValueError, match="phenotypes change"):
        motions_table_to_clips(changed)


def test_residual_summary_and_pooled_figures(retargeted):
    summary = residual_summary([retargeted])
    assert list(summary.columns) == ["clip", "subject", "frames", "median_mm", "p95_mm", "max_mm"]
    row = summary.iloc[0]
    assert row["frames"] == retargeted.frames
    assert row["median_mm"] == pytest.approx(np.median(retargeted.residual_mm))
    assert row["median_mm"] <= row["p95_mm"] <= row["max_mm"]
    pooled = pooled_residual_mm([retargeted, retargeted])
    assert pooled["median_mm"] == pytest.approx(row["median_mm"])


def test_plot_writes_a_png(tmp_path, synthetic_clip, retargeted):
    path = plot_retarget(synthetic_clip[0], retargeted, [0, 10], tmp_path / "retarget.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(ValueError, match="outside"):
        plot_retarget(synthetic_clip[0], retargeted, [retargeted.frames], tmp_path / "x.png")


def test_retargeted_clip_validates_its_arrays(retargeted):
    fields = {f.name: getattr(retargeted, f.name) for f in dataclasses.fields(RetargetedClip)}
    with pytest.raises(ValueError, match="keypoints_world_m must have shape"):
        RetargetedClip(**{**fields, "keypoints_world_m": fields["keypoints_world_m"][:, :10]})
    with pytest.raises(ValueError, match="non-finite"):
        bad = fields["root_translation_m"].copy()
        bad[0, 0] = np.inf
        RetargetedClip(**{**fields, "root_translation_m": bad})
    assert isinstance(SubjectFit, type)
