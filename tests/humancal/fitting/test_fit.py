"""The body fit on a small synthetic scene (true identities, true cameras, noisy triangulated joints)."""

import numpy as np
import pytest
import torch

from humancal.camera import CameraRig
from humancal.fitting import BodyFitConfig, FittingInputError, body_observations, fit_bodies
from humancal.prior import shipped_prior
from humancal.synthetic import generate_scene, preset
from humancal.tables.detections import detections_to_dense

FAST = BodyFitConfig(iterations_3d=150, iterations_global=5, iterations_body=15, cameras="fixed")


@pytest.fixture(scope="module")
def scene_inputs(body_model):
    scene = generate_scene(preset("demo", seed=3, num_people=2, num_views=3, num_frames=40), body_model,
                           sequence="fit")
    rng = np.random.default_rng(0)
    skeletons = scene.poses3d.assign(num_views=2)
    skeletons[["x_m", "y_m", "z_m"]] += rng.normal(0.0, 0.02, (len(skeletons), 3))  # 2 cm triangulation noise
    dense = detections_to_dense(scene.detections)
    observations, warnings = body_observations(dense, scene.associations, skeletons, len(scene.rig))
    return scene, observations, CameraRig.from_cameras(scene.rig)


def _errors(scene, motions):
    gt = scene.keypoints_world_m[:, motions.frames][np.searchsorted(scene.person_ids, motions.person_ids)]
    mpjpe = 1000 * np.linalg.norm(motions.keypoints_world_m - gt, axis=-1)[motions.present].mean()
    acc = lambda x: x[:, 2:] - 2 * x[:, 1:-1] + x[:, :-2]  # noqa: E731
    accel = 1000 * np.linalg.norm(acc(motions.keypoints_world_m) - acc(gt), axis=-1).mean()
    return mpjpe, accel


def test_prior_fit_recovers_the_people_and_is_smoother_than_raw_angles(body_model, scene_inputs):
    torch.manual_seed(0)
    scene, observations, rig = scene_inputs
    prior = shipped_prior()[0]
    fit = fit_bodies(body_model, observations, rig, prior, FAST, fps=30.0)
    raw = fit_bodies(body_model, observations, rig, None, FAST, fps=30.0)
    mpjpe, accel = _errors(scene, fit.motions)
    raw_mpjpe, raw_accel = _errors(scene, raw.motions)
    # the noisy joints are 2 cm (about 35 mm per joint) off; the fit through every view comes much closer
    assert mpjpe < 30.0, mpjpe
    assert fit.reprojection_error_px < 10.0
    assert accel < 0.5 * raw_accel, (accel, raw_accel)
    assert set(fit.stage_seconds) == {"bundle", "prepare", "fit3d", "cameras", "global", "body", "floor", "total"}
    assert fit.stage_seconds["cameras"] == 0.0 and fit.stage_seconds["bundle"] == 0.0  # fixed cameras
    np.testing.assert_array_equal(fit.cameras.K, rig.K)  # held
    assert {"reprojection", "latent", "local_linear", "shape", "root_smooth", "seam", "total"} <= set(fit.loss_terms)
    assert fit.latents is not None and fit.latents.shape[-1] == 32 and raw.latents is None
    assert np.all((fit.motions.phenotypes >= 0) & (fit.motions.phenotypes <= 1))
    rot = fit.motions.bone_rotmats_local
    np.testing.assert_allclose(rot @ np.swapaxes(rot, -1, -2), np.broadcast_to(np.eye(3), rot.shape), atol=1e-5)


def test_views_must_match_the_cameras(body_model, scene_inputs):
    scene, observations, rig = scene_inputs
    two = CameraRig.from_cameras(scene.rig[:2])
    with pytest.raises(FittingInputError, match="detections of 3 views, but 2 cameras"):
        fit_bodies(body_model, observations, two, None, FAST)


def test_global_stage_moves_only_the_roots_and_decodes_the_held_pose_once(body_model, scene_inputs):
    from humancal.fitting.problem import BodyFitProblem, run_stage

    scene, observations, rig = scene_inputs
    prior = shipped_prior()[0].to(dtype=body_model.dtype).eval()
    problem = BodyFitProblem(body_model, observations, rig, prior, FAST)
    problem.encode_pose()
    latents, shape = problem.pose_params.detach().clone(), problem.shape_logit.detach().clone()
    decodes = []
    decode = prior.decode
    prior.decode = lambda z: decodes.append(z.shape) or decode(z)
    try:
        with torch.no_grad():
            before = problem.terms("2d")["reprojection"]
        terms = run_stage(problem, "global", 3, None)
    finally:
        prior.decode = decode
    # one decoding for `before` and one for the whole stage (the held pose), however many evaluations its line
    # searches make
    assert len(decodes) == 2
    assert problem.held_pose is None
    assert torch.equal(problem.pose_params.detach(), latents) and torch.equal(problem.shape_logit.detach(), shape)
    assert terms["reprojection"] < float(before)


def test_latents_start_at_the_prior_mean_or_the_reference_pose(body_model, scene_inputs):
    from humancal.fitting.problem import BodyFitProblem

    scene, observations, rig = scene_inputs
    prior = shipped_prior()[0].to(dtype=body_model.dtype).eval()
    starts = {}
    for start in ("prior_mean", "reference_pose"):
        problem = BodyFitProblem(body_model, observations, rig, prior, FAST.replace(latent_start=start))
        problem.encode_pose()
        assert problem.latent and problem.pose_params.requires_grad
        starts[start] = problem.pose_params.detach()
    assert starts["prior_mean"].shape == starts["reference_pose"].shape
    assert starts["prior_mean"].abs().max() == 0
    assert starts["reference_pose"].abs().mean() > 0.1  # the reference pose (arms out) is far from the mean
    with pytest.raises(ValueError, match="latent_start"):
        BodyFitConfig(latent_start="zeros")


def test_half_rate_values_are_interpolated_linearly_in_time():
    from humancal.fitting.schedule import upsample_frames

    for num_frames in (9, 10):
        time = torch.arange(num_frames, dtype=torch.float64)
        line = torch.stack([3.0 * time - 1.0, -0.5 * time], dim=-1)[None]  # (1, T, 2), linear in time
        coarse = line[:, ::2]
        up = upsample_frames(coarse, num_frames)
        assert up.shape == line.shape
        if num_frames % 2:  # every frame lies between two coarse ones: exact
            torch.testing.assert_close(up, line)
        else:  # the last (odd) frame has no coarse frame after it: it keeps the last value
            torch.testing.assert_close(up[:, :-1], line[:, :-1])
            torch.testing.assert_close(up[:, -1], coarse[:, -1])


def test_half_rate_start_decodes_half_the_frames_and_fits_as_well(body_model, scene_inputs):
    from humancal.prior.windows import window_layout

    scene, observations, rig = scene_inputs
    prior = shipped_prior()[0]
    windows = FAST.replace(window_frames=16, window_overlap=4)  # 40 frames >= 2 windows: the half-rate start applies
    decoded = []
    decode = prior.decode
    prior.decode = lambda z: decoded.append(z.shape[0] * z.shape[1]) or decode(z)
    try:
        torch.manual_seed(0)
        full = fit_bodies(body_model, observations, rig, prior, windows.replace(half_rate_fraction_3d=0.0), fps=30.0)
        full_decoded, decoded[:] = list(decoded), []
        torch.manual_seed(0)
        half = fit_bodies(body_model, observations, rig, prior, windows.replace(half_rate_fraction_3d=2 / 3), fps=30.0)
    finally:
        prior.decode = decode
    # the first 100 fit3d steps (and the stage's final terms) decode the windows of 20 of the 40 frames (2 people),
    # the rest those of all 40
    per_person = {t: window_layout(t, 16, 4).num_windows * 16 for t in (20, 40)}
    assert decoded[:101] == [2 * per_person[20]] * 101 and decoded[101] == full_decoded[0] == 2 * per_person[40]
    mpjpe_full, accel_full = _errors(scene, full.motions)
    mpjpe_half, accel_half = _errors(scene, half.motions)
    assert mpjpe_half < 1.1 * mpjpe_full, (mpjpe_half, mpjpe_full)
    assert accel_half < 1.2 * accel_full, (accel_half, accel_full)
    with pytest.raises(ValueError, match="half_rate_fraction_3d"):
        FAST.replace(half_rate_fraction_3d=1.5)


def test_a_person_unseen_on_the_half_rate_frames_keeps_its_own_start(body_model, scene_inputs):
    from dataclasses import replace

    from humancal.fitting.problem import BodyFitProblem

    scene, observations, rig = scene_inputs
    valid = observations.joints_valid.copy()
    valid[1, ::2] = False  # person 1 triangulated on odd frames only
    observations = replace(observations, joints_valid=valid)
    prior = shipped_prior()[0].to(dtype=body_model.dtype).eval()
    config = FAST.replace(window_frames=16, window_overlap=4)
    full = BodyFitProblem(body_model, observations, rig, prior, config)
    full.encode_pose()
    coarse = BodyFitProblem(body_model, observations.every_other_frame(), rig, prior, config, time_stride=2)
    coarse.encode_pose()
    with torch.no_grad():
        coarse.translation += 1.0  # as if the half-rate steps had moved every root by a metre
    before = full.translation.detach().clone()
    full.take_half_rate(coarse)
    moved = (full.translation.detach() - before).norm(dim=-1).mean(dim=1)
    assert moved[0] > 0.5 and moved[1] == 0, moved  # person 0 takes the half-rate fit, person 1 keeps its start
