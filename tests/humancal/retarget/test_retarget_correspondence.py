"""The joint correspondence: the Daz table resolves, bad tables are refused, mapped points equal the body model's."""

import dataclasses

import numpy as np
import pytest
import roma
import torch

from humancal.keypoints import JOINT_INDEX
from humancal.mocap import MocapClip
from humancal.retarget import DAZ_CMU_LINKS, JointLink, RetargetConfig, mocap_targets_m, resolve_links
from humancal.retarget.plot import _PARENTS
from humancal.retarget.points import PointModel


@pytest.fixture(scope="module")
def resolved(body_model):
    return resolve_links(DAZ_CMU_LINKS, body_model.posed_bones, body_model.posed_parents)


@pytest.fixture(scope="module")
def points(body_model, resolved):
    return PointModel(body_model, resolved)


def test_daz_table_resolves_with_mirrored_twins(resolved, body_model):
    assert resolved.num_points == len(DAZ_CMU_LINKS) == 27
    for m, twin in enumerate(resolved.mirror):
        a, b = resolved.mocap_joints[m], resolved.mocap_joints[twin]
        if twin == m:
            assert a in ("hip", "abdomen", "chest", "neck", "head")
        else:
            assert {a[0], b[0]} == {"l", "r"} or {a[:4], b[:4]} == {"left", "righ"}
            assert resolved.offset_kind[m] == resolved.offset_kind[twin]
            assert resolved.weight[m] == resolved.weight[twin]
    # Joint centres that carry the bone lengths have no offset.
    plain = {resolved.mocap_joints[m] for m in range(resolved.num_points) if resolved.offset_kind[m] == "none"}
    assert plain == {"lShin", "rShin", "lFoot", "rFoot", "lForeArm", "rForeArm", "lHand", "rHand"}
    assert body_model.posed_bones[resolved.anchor_bone[resolved.mocap_joints.index("rShin")]] == "lowerleg01.R"
    assert resolved.anchor_keypoint[resolved.mocap_joints.index("leftEye")] == JOINT_INDEX["left_eye"]


@pytest.mark.parametrize(
    "change, message",
    [
        ({"anchor": "femur.L"}, "is not a posed bone"),
        ({"carrier": "spine01"}, "must be the bone itself or its parent"),
        ({"weight": 0.0}, "weight must be positive"),
        ({"offset": "sideways"}, "offset must be"),
        ({"mirror": "rHand"}, "mirror"),
        ({"offset": "along", "carrier": "lowerleg01.L"}, "'along' offset needs a carrier"),
    ],
)
def test_bad_tables_are_refused(body_model, change, message):
    links = list(DAZ_CMU_LINKS)
    row = [link.mocap_joint for link in links].index("lShin")
    links[row] = dataclasses.replace(links[row], **change)
    with pytest.raises(ValueError, match=message):
        resolve_links(links, body_model.posed_bones, body_model.posed_parents)


def test_duplicate_and_empty_tables_are_refused(body_model):
    with pytest.raises(ValueError, match="more than once"):
        resolve_links(DAZ_CMU_LINKS + DAZ_CMU_LINKS[:1], body_model.posed_bones, body_model.posed_parents)
    with pytest.raises(ValueError, match="empty"):
        resolve_links((), body_model.posed_bones, body_model.posed_parents)
    with pytest.raises(ValueError, match="not a canonical keypoint"):
        bad = JointLink("x", "left_pinky", "keypoint", carrier="head")
        resolve_links((bad,), body_model.posed_bones, body_model.posed_parents)


def test_mapped_points_without_offsets_are_the_body_models_joints_and_keypoints(body_model, points, resolved):
    generator = torch.Generator().manual_seed(3)
    rest = body_model.rest_skeleton(torch.rand(1, 6, generator=generator))
    rotmats = roma.rotvec_to_rotmat(0.5 * torch.randn(1, 5, 22, 3, generator=generator))
    translation = torch.randn(1, 5, 3, generator=generator)
    keypoints, joints = body_model.keypoints_and_joints(rest, rotmats, translation)
    zero = torch.zeros(resolved.num_points, 3)
    mapped = points.points(points.coefficients(rest, zero), rotmats[0], translation[0])
    for m in range(resolved.num_points):
        if resolved.anchor_bone[m] >= 0:
            expected = joints[0, :, resolved.anchor_bone[m]]
        else:
            expected = keypoints[0, :, resolved.anchor_keypoint[m]]
        torch.testing.assert_close(mapped[:, m], expected, atol=1e-5, rtol=0)


def test_offsets_rotate_with_their_carrier(body_model, points, resolved):
    rest = body_model.rest_skeleton(torch.full((1, 6), 0.5))
    offsets = torch.zeros(resolved.num_points, 3)
    m = resolved.mocap_joints.index("lIndex1")
    offsets[m] = torch.tensor([0.0, -0.1, 0.0])
    rotmats = body_model.identity_pose(1, 1)[0]
    quarter = torch.tensor([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # +90 deg about z
    rotmats[0, body_model.posed_bones.index("wrist.L")] = quarter
    moved = points.points(points.coefficients(rest, offsets), rotmats, torch.zeros(1, 3))
    still = points.points(points.coefficients(rest, offsets * 0), rotmats, torch.zeros(1, 3))
    torch.testing.assert_close(moved[0, m] - still[0, m], torch.tensor([0.1, 0.0, 0.0]), atol=1e-6, rtol=0)


def test_offset_basis_is_orthonormal_and_mirror_symmetric(body_model, points, resolved):
    rest = body_model.rest_skeleton(torch.full((1, 6), 0.5))
    basis = points.offset_basis(rest)
    kinds = points.offset_column_kinds()
    assert basis.shape == (3 * resolved.num_points, len(kinds))
    torch.testing.assert_close(basis.T @ basis, torch.eye(len(kinds), dtype=basis.dtype), atol=1e-12, rtol=0)
    offsets = (basis @ torch.linspace(-1, 1, len(kinds), dtype=basis.dtype)).reshape(-1, 3)
    for m, twin in enumerate(resolved.mirror):
        if resolved.offset_kind[m] == "free":
            expected = offsets[twin] * torch.tensor([-1.0, 1.0, 1.0], dtype=basis.dtype)
            torch.testing.assert_close(offsets[m], expected, atol=1e-12, rtol=0)
        if resolved.offset_kind[m] == "none":
            assert torch.all(offsets[m] == 0)
    assert offsets[resolved.mocap_joints.index("neck"), 0].abs() < 1e-9  # midline


def test_plot_parents_match_the_body_model(body_model):
    assert _PARENTS == tuple(body_model.posed_parents)


def test_targets_name_missing_joints_and_the_end_site_hint():
    clip = MocapClip("02_01", "02", ("hip", "lShin"), (-1, 0), np.zeros((2, 2, 3)), 30.0)
    with pytest.raises(ValueError, match=r"lacks the mapped mocap joint\(s\) \['lFoot_end'\].*include_end_sites"):
        mocap_targets_m(clip, ("lShin", "lFoot_end"))
    with pytest.raises(ValueError, match="expected a humancal.mocap.MocapClip"):
        mocap_targets_m(np.zeros((2, 2, 3)), ("lShin",))


def test_targets_refuse_non_finite_positions():
    clip = MocapClip("02_01", "02", ("hip", "lShin"), (-1, 0), np.zeros((3, 2, 3)), 30.0)
    broken = clip.positions_world_m.copy()
    broken[1, 1, 2] = np.nan
    object.__setattr__(clip, "positions_world_m", broken)  # MocapClip itself refuses NaN; bypass it on purpose
    with pytest.raises(ValueError, match="non-finite, first at frame 1, joint 'lShin'"):
        mocap_targets_m(clip, ("lShin",))


def test_config_is_validated():
    with pytest.raises(ValueError, match="pose_iterations must be a positive int"):
        RetargetConfig(pose_iterations=0)
    with pytest.raises(ValueError, match="phenotype 1"):
        RetargetConfig(phenotype_init=(0.5, 0.2, 0.5, 0.5, 0.3, 0.5))
    with pytest.raises(ValueError, match="smooth_weight must be a number >= 0"):
        RetargetConfig(smooth_weight=-1.0)
    assert RetargetConfig.tiny().shape_frames < RetargetConfig().shape_frames
