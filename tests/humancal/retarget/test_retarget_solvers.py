"""The pose solvers: analytic derivatives equal autograd, Levenberg-Marquardt recovers known poses, deterministic."""

import numpy as np
import pytest
import roma
import torch

from humancal.retarget import RetargetConfig, resolve_links
from humancal.retarget.init import analytic_pose_init
from humancal.retarget.levenberg import PointStructure, _Neighbours, frame_costs
from humancal.retarget.priors import PoseWeights
from humancal.retarget.offsets import fit_poses_and_offsets
from humancal.retarget.points import PointModel
from humancal.retarget.pose import solve_poses

F64 = torch.float64


@pytest.fixture(scope="module")
def points(body_model):
    resolved = resolve_links(RetargetConfig().links, body_model.posed_bones, body_model.posed_parents)
    return PointModel(body_model, resolved)


@pytest.fixture(scope="module")
def random_problem(body_model, points):
    generator = torch.Generator().manual_seed(7)
    rest = body_model.rest_skeleton(torch.rand(1, 6, generator=generator))
    offsets = 0.03 * torch.randn(points.num_points, 3, generator=generator, dtype=F64)
    coefficients = points.coefficients(rest, offsets)
    rotmats = roma.rotvec_to_rotmat(torch.randn(4, 22, 3, generator=generator, dtype=F64))
    translation = torch.randn(4, 3, generator=generator, dtype=F64)
    targets = translation[:, None] + 0.5 * torch.randn(4, points.num_points, 3, generator=generator, dtype=F64)
    previous = (roma.rotvec_to_rotmat(torch.randn(22, 3, generator=generator, dtype=F64)), torch.zeros(3, dtype=F64))
    return coefficients, rotmats, translation, targets, previous


def test_gauss_newton_gradient_and_hessian_equal_autograd(points, random_problem):
    coefficients, rotmats, translation, targets, previous = random_problem
    structure = PointStructure(coefficients, points.subtree)
    bone_prior = torch.linspace(0.1, 0.5, 22, dtype=F64)
    bone_prior[0] = 0.0
    hinges = torch.tensor([4, 18])
    axes = torch.nn.functional.normalize(torch.tensor([[1.0, 0.2, 0.1], [-0.7, 0.0, -0.7]], dtype=F64), dim=-1)
    directions = torch.nn.functional.normalize(torch.tensor([[0.0, 1.0, -0.2], [0.5, 0.3, -0.5]], dtype=F64), dim=-1)
    weights = PoseWeights(bone_prior, 0.2, hinges, axes, directions, 0.7, 0.4)  # large, to test the derivatives
    neighbours = _Neighbours(rotmats, translation, previous)
    cost, rotations, gradient, hessian, jacobian, residual = frame_costs(
        points, coefficients, structure, rotmats, translation, targets, weights, neighbours, True, True
    )
    # Increments: translation, then world-axis rotations eta_b = G_b omega_b.
    step = torch.zeros(4, 69, dtype=F64, requires_grad=True)
    local = (rotations.transpose(-1, -2) @ step[:, 3:].reshape(4, 22, 3, 1))[..., 0]
    moved = frame_costs(points, coefficients, structure, rotmats @ roma.rotvec_to_rotmat(local),
                        translation + step[:, :3], targets, weights, neighbours)
    torch.testing.assert_close(moved.detach(), cost)
    moved.sum().backward()
    torch.testing.assert_close(step.grad / 2, gradient, atol=1e-10, rtol=1e-10)

    def weighted_residual(x):
        local_x = (rotations[1].transpose(-1, -2) @ x[3:].reshape(22, 3, 1))[..., 0]
        p = points.points(coefficients, rotmats[1:2] @ roma.rotvec_to_rotmat(local_x)[None], translation[1:2] + x[:3])
        return ((p - targets[1:2]) * points.weight.to(F64).sqrt()[None, :, None]).reshape(-1)

    exact = torch.func.jacrev(weighted_residual)(torch.zeros(69, dtype=F64))
    torch.testing.assert_close(jacobian[1], exact, atol=1e-12, rtol=0)
    torch.testing.assert_close(residual[1], weighted_residual(torch.zeros(69, dtype=F64)), atol=1e-12, rtol=0)
    no_regularisers = frame_costs(points, coefficients, structure, rotmats, translation, targets,
                                  PoseWeights(torch.zeros(22, dtype=F64), 0.0), None, True)[3]
    torch.testing.assert_close(no_regularisers[1], exact.T @ exact, atol=1e-10, rtol=0)


def test_levenberg_marquardt_recovers_known_poses(body_model, points, synthetic_clip):
    clip, truth = synthetic_clip
    coefficients = points.coefficients(truth["rest"], torch.as_tensor(truth["offsets_m"]))
    targets = torch.tensor(clip.positions_world_m)
    # Nearly no regularisation: the solver itself must reach the exact answer.
    exact = RetargetConfig(pose_iterations=10, chunk_frames=20, pose_prior_weight=1e-9, smooth_weight=1e-9,
                           hinge_prior_weight=0.0)
    rotmats, translation, _ = solve_poses(points, coefficients, targets, exact, smooth=True)
    residual_mm = (points.points(coefficients, rotmats, translation) - targets).norm(dim=-1) * 1000
    assert float(residual_mm.max()) < 0.2
    # The default priors (a small pull to the rest pose, smoothness) cost at most a few mm.
    config = RetargetConfig(chunk_frames=20)  # several chunks, tied by smoothness
    start, _ = analytic_pose_init(points, coefficients, targets, config.init_child_weight)
    default = solve_poses(points, coefficients, targets, config, smooth=True)
    default_mm = (points.points(coefficients, default[0], default[1]) - targets).norm(dim=-1) * 1000
    assert float(default_mm.median()) < 0.5 and float(default_mm.quantile(0.95)) < 2.0 and float(default_mm.max()) < 6.0
    # Every bone head lands where the truth has it, and the bones whose orientation the points fix in full (the
    # pelvis by the hip joints, the head by the eyes) turn as the truth does; twists about a bone's own axis
    # (3-DOF knees and elbows make the thigh and upper-arm twist unobservable) need not. (The hands are left out:
    # the random synthetic knuckle offsets can put both knuckles nearly in line with the wrist.)
    truth_rotmats = torch.as_tensor(truth["rotmats"])
    joints = body_model.joints(truth["rest"], default[0].float()[None], default[1].float()[None])[0]
    truth_joints = body_model.joints(truth["rest"], truth_rotmats.float()[None],
                                     torch.as_tensor(truth["translation"]).float()[None])[0]
    assert float((joints - truth_joints).norm(dim=-1).max()) < 0.005
    world, _ = points.world_transforms(coefficients, default[0], default[1])
    truth_world, _ = points.world_transforms(coefficients, truth_rotmats, torch.as_tensor(truth["translation"]))
    angles = torch.rad2deg(roma.rotmat_geodesic_distance(world, truth_world))
    fixed = [body_model.posed_bones.index(b) for b in ("root", "head")]
    assert float(angles[:, fixed].max()) < 3.0


def test_pose_fit_is_deterministic(points, synthetic_clip):
    clip, truth = synthetic_clip
    coefficients = points.coefficients(truth["rest"], torch.as_tensor(truth["offsets_m"]))
    targets = torch.tensor(clip.positions_world_m)
    first = solve_poses(points, coefficients, targets, RetargetConfig.tiny(), smooth=True)
    second = solve_poses(points, coefficients, targets, RetargetConfig.tiny(), smooth=True)
    for a, b in zip(first, second):
        assert torch.equal(a, b)


def test_joint_poses_and_offsets_solve_recovers_the_points(body_model, points, synthetic_clip):
    clip, truth = synthetic_clip
    rest = truth["rest"]
    targets = torch.tensor(clip.positions_world_m)[::3]
    basis = points.offset_basis(rest)
    zero = torch.zeros(points.num_points, 3, dtype=F64)
    rotmats, translation, _ = solve_poses(points, points.coefficients(rest, zero), targets, RetargetConfig(), False)
    before = (points.points(points.coefficients(rest, zero), rotmats, translation) - targets).norm(dim=-1)
    weights = points.offset_prior_weights(1e-6, 1e-6)
    coords0 = torch.zeros(basis.shape[1], dtype=F64)
    pose_weights = PoseWeights(torch.full((22,), 1e-6, dtype=F64), 0.0)
    rotmats, translation, coords, _ = fit_poses_and_offsets(
        points, rest, rotmats, translation, coords0, targets, pose_weights, weights, 30
    )
    offsets = (basis @ coords).reshape(-1, 3)
    after = (points.points(points.coefficients(rest, offsets), rotmats, translation) - targets).norm(dim=-1)
    assert float(before.median()) > 0.005
    assert float(after.max()) < 1e-3
    along = [m for m, kind in enumerate(points.resolved.offset_kind) if kind == "along"]
    np.testing.assert_allclose(offsets[along].numpy(), truth["offsets_m"][along], atol=1e-3)
