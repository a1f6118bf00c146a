"""BodyModel: the fast keypoint path equals anny's full forward, gradients flow, inputs are validated."""

import math

import pytest
import roma
import torch

from humancal.body import PHENOTYPE_NAMES, POSED_BONE_SPEC, BodyModel, RestSkeleton
from humancal.keypoints import JOINT_INDEX, NUM_JOINTS

TOLERANCE_M = 1e-5


def random_pose(model: BodyModel, num_people: int, num_frames: int, generator: torch.Generator, max_angle_rad=1.0):
    """Random posed-bone rotations (up to max_angle per bone, any root orientation) and root translations."""
    shape = (num_people, num_frames, model.num_posed_bones)
    axes = torch.nn.functional.normalize(torch.randn(*shape, 3, generator=generator), dim=-1)
    angles = max_angle_rad * torch.rand(*shape, 1, generator=generator)
    angles[:, :, 0] = math.pi * torch.rand(num_people, num_frames, 1, generator=generator)
    rotations = roma.rotvec_to_rotmat(axes * angles)
    translations = torch.randn(num_people, num_frames, 3, generator=generator) * 2.0
    return rotations, translations


@pytest.fixture(scope="module")
def generator():
    return torch.Generator().manual_seed(1234)


def test_posed_bones_are_a_tree_root_first(body_model):
    assert body_model.posed_bones[0] == "root"
    assert len(body_model.posed_bones) == len(body_model.posed_parents) == 22
    assert body_model.posed_parents[0] == -1
    assert all(0 <= p < b for b, p in enumerate(body_model.posed_parents) if b > 0)
    parent_of = dict(zip(body_model.posed_bones, body_model.posed_parents))
    assert body_model.posed_bones[parent_of["lowerleg01.L"]] == "upperleg01.L"
    assert body_model.posed_bones[parent_of["toes.R"]] == "foot.R"
    assert body_model.posed_bones[parent_of["head"]] == "neck01"
    assert body_model.posed_bones[parent_of["upperarm01.L"]] == "clavicle.L"
    anny_labels = set(body_model.anny_model.bone_labels)
    assert all(b in anny_labels for _, bones in POSED_BONE_SPEC for b in bones)


@pytest.mark.parametrize("phenotype_kind", ["random", "corners"])
def test_fast_path_equals_anny_full_forward(body_model, generator, phenotype_kind):
    num_people, num_frames = 3, 4
    if phenotype_kind == "random":
        phenotypes = torch.rand(num_people, 6, generator=generator)
    else:  # the ends of every phenotype range, where anny's interpolation switches anchors
        phenotypes = torch.tensor([[0.0] * 6, [1.0] * 6, [0.0, 1.0, 0.0, 1.0, 0.0, 1.0]])
    rotations, translations = random_pose(body_model, num_people, num_frames, generator)
    rest = body_model.rest_skeleton(phenotypes)
    keypoints, joints = body_model.keypoints_and_joints(rest, rotations, translations)
    reference = body_model.reference_forward(phenotypes, rotations, translations)

    assert keypoints.shape == (num_people, num_frames, NUM_JOINTS, 3)
    assert joints.shape == (num_people, num_frames, body_model.num_posed_bones, 3)
    assert reference["vertices"].shape == (num_people, num_frames, body_model.num_vertices, 3)
    torch.testing.assert_close(keypoints, reference["keypoints"], atol=TOLERANCE_M, rtol=0)
    torch.testing.assert_close(joints, reference["joints"], atol=TOLERANCE_M, rtol=0)
    torch.testing.assert_close(body_model.keypoints(rest, rotations, translations), keypoints, atol=0, rtol=0)
    torch.testing.assert_close(body_model.joints(rest, rotations, translations), joints, atol=0, rtol=0)
    # The root joint is the root translation, by definition.
    torch.testing.assert_close(joints[:, :, 0], translations, atol=TOLERANCE_M, rtol=0)
    # The pose moved the keypoints far from the identity pose, so the agreement is not trivial.
    identity = body_model.keypoints(rest, body_model.identity_pose(num_people, num_frames), translations)
    assert (keypoints - identity).norm(dim=-1).amax() > 0.3


def test_float64_model_is_exact_to_round_off(generator):
    model = BodyModel(dtype=torch.float64)
    phenotypes = torch.rand(2, 6, generator=generator, dtype=torch.float64)
    rotations, translations = random_pose(model, 2, 3, generator)
    rotations, translations = rotations.double(), translations.double()
    rest = model.rest_skeleton(phenotypes)
    reference = model.reference_forward(phenotypes, rotations, translations)
    error = (model.keypoints(rest, rotations, translations) - reference["keypoints"]).abs().amax()
    assert error < 1e-10, f"fast path differs from anny by {float(error):.3g} m in float64"


def test_gradients_flow_and_match_the_reference(body_model, generator):
    phenotypes = (0.1 + 0.8 * torch.rand(2, 6, generator=generator)).requires_grad_()
    rotvecs = (0.5 * torch.randn(2, 3, body_model.num_posed_bones, 3, generator=generator)).requires_grad_()
    translations = torch.randn(2, 3, 3, generator=generator).requires_grad_()
    target = torch.randn(2, 3, NUM_JOINTS, 3, generator=generator)

    def gradients(fast: bool):
        rotations = roma.rotvec_to_rotmat(rotvecs)
        if fast:
            keypoints = body_model.keypoints(body_model.rest_skeleton(phenotypes), rotations, translations)
        else:
            keypoints = body_model.reference_forward(phenotypes, rotations, translations)["keypoints"]
        loss = ((keypoints - target) ** 2).sum()
        return torch.autograd.grad(loss, (phenotypes, rotvecs, translations))

    fast = gradients(fast=True)
    reference = gradients(fast=False)
    for name, grad_fast, grad_ref in zip(("phenotypes", "rotations", "translation"), fast, reference):
        assert torch.isfinite(grad_fast).all(), name
        assert grad_fast.abs().amax() > 1e-4, f"no gradient reaches {name}"
        torch.testing.assert_close(grad_fast, grad_ref, atol=2e-4, rtol=2e-3, msg=f"gradient of {name}")
    # Every posed bone but the wrists (whose keypoint share is small but non-zero) moves some keypoint.
    assert (fast[1].abs().sum(dim=(0, 1, 3)) > 0).all()


def test_reference_pose_convention(body_model):
    """Identity pose: upright, facing -y, left side at +x, root head at the translation."""
    phenotypes = torch.full((1, 6), 0.5)
    rest = body_model.rest_skeleton(phenotypes)
    keypoints = body_model.keypoints(rest, body_model.identity_pose(1, 1), torch.zeros(1, 1, 3))[0, 0]
    nose, left_ankle = keypoints[JOINT_INDEX["nose"]], keypoints[JOINT_INDEX["left_ankle"]]
    assert nose[2] - left_ankle[2] > 1.2
    assert keypoints[JOINT_INDEX["left_shoulder"], 0] > 0.1 > -0.1 > keypoints[JOINT_INDEX["right_shoulder"], 0]
    assert nose[1] < keypoints[JOINT_INDEX["left_ear"], 1] - 0.05  # the face points to -y
    assert keypoints[JOINT_INDEX["left_big_toe"], 1] < keypoints[JOINT_INDEX["left_heel"], 1] - 0.1
    torch.testing.assert_close(rest.bone_heads_m[0, 0], torch.zeros(3))


def test_knee_flexes_about_plus_x(body_model):
    """The documented axis convention: +x rotation of lowerleg01 moves the ankle backwards (+y)."""
    rest = body_model.rest_skeleton(torch.full((1, 6), 0.5))
    pose = body_model.identity_pose(1, 1)
    pose[0, 0, body_model.posed_bones.index("lowerleg01.L")] = roma.rotvec_to_rotmat(torch.tensor([1.0, 0.0, 0.0]))
    zero = torch.zeros(1, 1, 3)
    moved = body_model.keypoints(rest, pose, zero) - body_model.keypoints(rest, body_model.identity_pose(1, 1), zero)
    ankle = moved[0, 0, JOINT_INDEX["left_ankle"]]
    assert ankle[1] > 0.25 and ankle[2] > 0.1
    assert moved[0, 0, JOINT_INDEX["right_ankle"]].abs().amax() < 1e-6


def test_rest_skeleton_shapes_and_weights(body_model, generator):
    rest = body_model.rest_skeleton(torch.rand(4, 6, generator=generator))
    assert isinstance(rest, RestSkeleton)
    assert rest.num_people == 4
    assert rest.bone_heads_m.shape == (4, body_model.num_posed_bones, 3)
    assert rest.chain_offsets_m.shape == (4, body_model.num_posed_bones, 3)
    assert rest.keypoint_linear_m.shape == (4, NUM_JOINTS, body_model.num_posed_bones, 3)
    assert rest.keypoint_affine.shape == (4, NUM_JOINTS, body_model.num_posed_bones)
    torch.testing.assert_close(rest.keypoint_affine.sum(-1), torch.ones(4, NUM_JOINTS))
    subset = rest.select([2, 0])
    assert subset.num_people == 2
    torch.testing.assert_close(subset.keypoint_linear_m[1], rest.keypoint_linear_m[0])
    assert not rest.detach().keypoint_linear_m.requires_grad
    # The toes groups fold their extra bones' heads into the foot: both keypoints of the toes read the foot.
    foot = body_model.posed_bones.index("foot.L")
    assert rest.keypoint_affine[0, JOINT_INDEX["left_small_toe"], foot] > 0.99


def test_height_plausible_and_monotone_in_height_phenotype(body_model):
    heights_phenotype = torch.linspace(0.0, 1.0, 6)
    phenotypes = torch.full((6, 6), 0.5)
    phenotypes[:, PHENOTYPE_NAMES.index("age")] = 2 / 3  # young adult
    phenotypes[:, PHENOTYPE_NAMES.index("height")] = heights_phenotype
    height = body_model.height_m(phenotypes)
    assert height.shape == (6,)
    # anny's height phenotype spans MakeHuman's extremes: about 1.3 m to 2.4 m for a young adult.
    assert ((height > 1.2) & (height < 2.5)).all(), height
    assert (height.diff() > 0.1).all(), height
    # anny's gender runs from male (0) to female (1); at equal settings the male is taller.
    young_adults = torch.tensor([[0.0, 2 / 3, 0.5, 0.5, 0.5, 0.5], [1.0, 2 / 3, 0.5, 0.5, 0.5, 0.5]])
    male, female = body_model.height_m(young_adults)
    assert 1.7 < float(male) < 2.0 and float(female) < float(male) - 0.05


def test_root_height_puts_soles_on_the_floor(body_model, generator):
    phenotypes = torch.rand(2, 6, generator=generator)
    root_height = body_model.root_height_m(phenotypes)
    translations = torch.zeros(2, 1, 3)
    translations[:, 0, 2] = root_height
    vertices = body_model.reference_forward(phenotypes, body_model.identity_pose(2, 1), translations)["vertices"]
    torch.testing.assert_close(vertices[..., 2].amin(dim=-1), torch.zeros(2, 1), atol=1e-5, rtol=0)
    assert ((root_height > 0.3) & (root_height < 1.3)).all()


def test_faces_index_the_mesh(body_model):
    assert body_model.faces.ndim == 2 and body_model.faces.shape[1] == 3
    assert body_model.faces.dtype == torch.int64
    assert int(body_model.faces.min()) == 0 and int(body_model.faces.max()) == body_model.num_vertices - 1


@pytest.mark.parametrize(
    ("argument", "bad", "message"),
    [
        ("phenotypes", torch.full((2, 5), 0.5), r"phenotypes must have shape \(P, 6\)"),
        ("phenotypes", torch.full((2, 6), 1.2), r"phenotypes must lie in \[0, 1\]"),
        ("phenotypes", torch.full((2, 6), -0.1), r"out of range: \['gender'"),
        ("phenotypes", torch.full((2, 6), float("nan")), "phenotypes must be finite"),
        ("phenotypes", torch.full((2, 6), 0.5, dtype=torch.float64), "phenotypes must be torch.float32"),
        ("phenotypes", [[0.5] * 6], "phenotypes must be a torch.Tensor"),
        ("rotations", torch.eye(3).expand(2, 3, 21, 3, 3), r"bone_rotmats_local must have shape \(2, F, 22, 3, 3\)"),
        ("rotations", torch.eye(3).expand(3, 3, 22, 3, 3), r"bone_rotmats_local must have shape \(2, F, 22, 3, 3\)"),
        ("rotations", torch.full((2, 3, 22, 3, 3), float("nan")), "bone_rotmats_local must be finite"),
        ("translations", torch.zeros(2, 4, 3), r"root_translation_m must have shape \(2, 3, 3\)"),
        ("translations", torch.full((2, 3, 3), float("inf")), "root_translation_m must be finite"),
    ],
)
def test_bad_inputs_raise_value_error(body_model, argument, bad, message):
    phenotypes = torch.full((2, 6), 0.5)
    rotations = body_model.identity_pose(2, 3)
    translations = torch.zeros(2, 3, 3)
    if argument == "phenotypes":
        with pytest.raises(ValueError, match=message):
            body_model.rest_skeleton(bad)
        with pytest.raises(ValueError, match=message):
            body_model.reference_forward(bad, rotations, translations)
        return
    rest = body_model.rest_skeleton(phenotypes)
    if argument == "rotations":
        rotations = bad
    else:
        translations = bad
    for call in (body_model.keypoints, body_model.joints):
        with pytest.raises(ValueError, match=message):
            call(rest, rotations, translations)
    with pytest.raises(ValueError, match=message):
        body_model.reference_forward(phenotypes, rotations, translations)


def test_rest_argument_must_be_a_rest_skeleton(body_model):
    with pytest.raises(ValueError, match="rest must be a RestSkeleton"):
        body_model.keypoints(torch.zeros(1, 6), body_model.identity_pose(1, 1), torch.zeros(1, 1, 3))


def test_keypoint_offsets_turn_with_their_dominant_bone(body_model, generator):
    rest = body_model.rest_skeleton(torch.full((2, 6), 0.5, dtype=body_model.dtype))
    rotations, translations = random_pose(body_model, 2, 3, generator)
    rotations, translations = rotations.to(body_model.dtype), translations.to(body_model.dtype)
    plain = body_model.keypoints(rest, rotations, translations)
    zero = body_model.keypoints(rest.with_keypoint_offsets(torch.zeros(NUM_JOINTS, 3, dtype=body_model.dtype)),
                                rotations, translations)
    torch.testing.assert_close(zero, plain)
    hip = JOINT_INDEX["left_hip"]
    bone = int(rest.dominant_bones()[0, hip])
    assert body_model.posed_bones[bone] == "upperleg01.L"
    offsets = torch.zeros(NUM_JOINTS, 3, dtype=body_model.dtype)
    offsets[hip] = torch.tensor([0.02, -0.01, 0.03], dtype=body_model.dtype)
    moved = body_model.keypoints(rest.with_keypoint_offsets(offsets), rotations, translations)
    # the world rotation of the upper leg: the chain of local rotations from the root (local-ref composition)
    chain, b = [], bone
    while b >= 0:
        chain.append(b)
        b = body_model.posed_parents[b]
    world = rotations[:, :, chain[-1]]
    for b in reversed(chain[:-1]):
        world = world @ rotations[:, :, b]
    torch.testing.assert_close(body_model.bone_world_rotations(rest, rotations, translations)[:, :, bone], world)
    expected = plain.clone()
    expected[:, :, hip] += torch.einsum("pfij,j->pfi", world, offsets[hip])
    torch.testing.assert_close(moved, expected, atol=TOLERANCE_M, rtol=0)
    with pytest.raises(ValueError, match="offsets_m must have shape"):
        rest.with_keypoint_offsets(torch.zeros(NUM_JOINTS, 2, dtype=body_model.dtype))
