"""Fitting body motions to corrupted keypoints: through the motion prior's latents, or through raw joint angles.

The body is known (the rest skeleton of each person's phenotypes); per frame the fit optimizes the root
orientation (6D) and translation and the pose of the 21 other posed bones, parameterized either

* by the latent codes z (P, T, latent_dim) of a :class:`~humancal.prior.MotionVAE`, decoded to the 21 bones
  (the prior fit; the per-frame VAE variant gives the per-frame prior fit), with the latent regularizers
  ``weight_latent * mean(z^2) + weight_local_linear * mean((z[t+1] - 2 z[t] + z[t-1])^2)``, or
* by the 21 bones' 6D rotations directly (the no-prior fit), with only a small decay toward the reference pose.

The data term is the mean squared residual of the visible keypoints in units of the observations' noise scale:
3D keypoints in metres, or 2D keypoints in pixels seen by known cameras. The root gets the same small
second-difference penalty in every method, so that comparisons between methods are about the body pose.

Optimisation: Adam with a learning rate decaying linearly to a tenth, from a root initialized by a weighted
rigid fit of the reference pose's torso and head keypoints to the observations (triangulated first in 2D)
and the reference body pose (no-prior) or the prior's encoding of it (prior fits).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np
import roma
import torch
from torch import Tensor

from humancal.body import BodyModel, RestSkeleton
from humancal.camera import CameraRig
from humancal.camera.projection import project_points_torch
from humancal.config import Config, at_least, in_range, positive
from humancal.geometry.triangulation import triangulate_dlt
from humancal.keypoints import JOINT_INDEX, NUM_JOINTS
from humancal.prior.config import NUM_PRIOR_BONES
from humancal.prior.model import MotionVAE, identity_pose6d, pose6d_to_rotmats, rotmats_to_pose6d, with_root

__all__ = ["FitConfig", "KeypointObservations", "FitResult", "fit_motion", "initial_root"]

log = logging.getLogger(__name__)

_ROOT_POINTS = {"left_shoulder": 1.0, "right_shoulder": 1.0, "left_hip": 1.0, "right_hip": 1.0,
                "nose": 0.3, "left_ear": 0.3, "right_ear": 0.3}
"""Keypoints (and weights) of the rigid root initialization: the torso, and the head a little."""
_MAX_FROM_MEDIAN_M = 1.5


@dataclass(frozen=True)
class FitConfig(Config):
    """Weights and optimisation of one fit (:func:`fit_motion`).

    Attributes:
        iterations: Adam steps.
        learning_rate: initial Adam learning rate (decays linearly to a tenth).
        weight_latent: weight of ``mean(z^2)`` (prior fits; the prior's N(0, I)).
        weight_local_linear: weight of the mean squared latent second difference (prior fits).
        weight_rest: weight of the mean squared 6D offset of the 21 bones from the reference pose (no-prior fit).
        weight_root_smooth: weight of the mean squared second difference of the root translation (in units of
            ``root_smooth_scale_m``) and of its 6D orientation (in units of ``root_smooth_scale_m`` per metre), in
            every method.
        root_smooth_scale_m: scale of the root's second difference, metres per frame^2.
    """

    iterations: int = field(default=300, metadata=in_range(1, 1_000_000, integer=True))
    learning_rate: float = field(default=0.05, metadata=positive())
    weight_latent: float = field(default=1e-3, metadata=at_least(0))
    weight_local_linear: float = field(default=1.0, metadata=at_least(0))
    weight_rest: float = field(default=1e-4, metadata=at_least(0))
    weight_root_smooth: float = field(default=0.1, metadata=at_least(0))
    root_smooth_scale_m: float = field(default=0.01, metadata=positive())


@dataclass(frozen=True)
class KeypointObservations:
    """Corrupted canonical keypoints of P people over T frames: in 3D, or in 2D through V known cameras.

    Attributes:
        points: (P, T, 23, 3) world metres, or (V, P, T, 23, 2) pixels.
        visible: (P, T, 23) or (V, P, T, 23) bool; False marks a missing keypoint (its ``points`` are ignored).
        noise_scale: the data term's unit: metres (3D) or pixels (2D), e.g. the noise's standard deviation.
        cameras: the V cameras of 2D observations (a list is taken as a rig); None for 3D.
    """

    points: Tensor
    visible: Tensor
    noise_scale: float
    cameras: CameraRig | None = None

    def __post_init__(self) -> None:
        if self.cameras is not None:
            object.__setattr__(self, "cameras", CameraRig.of(self.cameras))
        dims = 2 if self.cameras else 3
        lead = 4 if self.cameras else 3
        if not isinstance(self.points, Tensor) or self.points.ndim != lead + 1 or self.points.shape[-1] != dims \
                or self.points.shape[-2] != NUM_JOINTS:
            shape = "(V, P, T, 23, 2) pixels" if self.cameras else "(P, T, 23, 3) metres"
            got = tuple(self.points.shape) if isinstance(self.points, Tensor) else type(self.points).__name__
            raise ValueError(f"KeypointObservations.points must have shape {shape}, got {got}")
        if self.cameras and self.points.shape[0] != len(self.cameras):
            raise ValueError(f"KeypointObservations: {len(self.cameras)} cameras but points of {self.points.shape[0]} views")
        if not isinstance(self.visible, Tensor) or self.visible.dtype != torch.bool \
                or tuple(self.visible.shape) != tuple(self.points.shape[:-1]):
            raise ValueError(f"KeypointObservations.visible must be a bool tensor of shape {tuple(self.points.shape[:-1])}")
        if not math.isfinite(self.noise_scale) or self.noise_scale <= 0:
            raise ValueError(f"KeypointObservations.noise_scale={self.noise_scale!r} must be > 0")

    @property
    def is_2d(self) -> bool:
        return bool(self.cameras)

    @property
    def num_people(self) -> int:
        return int(self.points.shape[-4])

    @property
    def num_frames(self) -> int:
        return int(self.points.shape[-3])


@dataclass(frozen=True)
class FitResult:
    """A fitted motion (detached tensors).

    Attributes:
        bone_rotmats_local: (P, T, 22, 3, 3) posed-bone rotations, root first.
        root_translation_m: (P, T, 3) metres.
        keypoints_m: (P, T, 23, 3) the fitted body's keypoints, world metres.
        latents: (P, T, latent_dim) the fitted latent codes (prior fits), else None.
        final_loss: the objective at the last step.
        seconds: wall time of the fit.
    """

    bone_rotmats_local: Tensor
    root_translation_m: Tensor
    keypoints_m: Tensor
    latents: Tensor | None
    final_loss: float
    seconds: float


def _second_difference(x: Tensor) -> Tensor:
    """(P, T, ...) -> (P, T - 2, ...); empty when T < 3."""
    return x[:, 2:] - 2.0 * x[:, 1:-1] + x[:, :-2]


def _mean_square(x: Tensor) -> Tensor:
    return (x**2).mean() if x.numel() else x.new_zeros(())


def _fill_invalid(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Per person, copy each invalid frame's value from the nearest valid frame (identity where none is)."""
    out = values.copy()
    for p in range(values.shape[0]):
        good = np.flatnonzero(valid[p])
        if good.size == 0:
            continue
        frames = np.arange(values.shape[1])
        nearest = good[np.abs(frames[:, None] - good[None, :]).argmin(axis=1)]
        out[p] = values[p, nearest]
    return out


def _observed_points_3d(observations: KeypointObservations) -> tuple[np.ndarray, np.ndarray]:
    """(P, T, 23, 3) metres and (P, T, 23) validity: the 3D points, or the 2D ones triangulated."""
    if not observations.is_2d:
        return observations.points.detach().cpu().double().numpy(), observations.visible.cpu().numpy()
    V, P, T, J, _ = observations.points.shape
    pixels = observations.points.detach().cpu().double().numpy().reshape(V, P * T * J, 2)
    weights = observations.visible.cpu().numpy().reshape(V, P * T * J).astype(np.float64)
    points, views = triangulate_dlt(observations.cameras, pixels, weights, min_views=2)
    points, valid = points.reshape(P, T, J, 3), ((views >= 2) & np.isfinite(points).all(axis=-1)).reshape(P, T, J)
    # Two views facing each other see a point along nearly the same ray: its triangulation can land metres away.
    # Keep the points within 1.5 m of the frame's median point (a body is smaller than that around its middle).
    masked = np.where(valid[..., None], points, np.nan)
    with np.errstate(all="ignore"):
        centre = np.nanmedian(masked, axis=2, keepdims=True)
    valid &= np.linalg.norm(np.nan_to_num(points - centre, nan=np.inf), axis=-1) < _MAX_FROM_MEDIAN_M
    return np.nan_to_num(points), valid


def initial_root(body: BodyModel, rest: RestSkeleton, observations: KeypointObservations) -> tuple[Tensor, Tensor]:
    """Root orientation and translation per frame from a weighted rigid fit of the reference pose.

    The reference pose's torso and head keypoints (root at the origin) are registered per frame onto the
    observed ones (2D observations are triangulated first); frames with fewer than three usable points copy
    the nearest frame that has them.

    Args:
        body: the body model.
        rest: the P people's rest skeleton.
        observations: the corrupted keypoints.

    Returns:
        ``(root_rotmats, root_translation_m)``: (P, T, 3, 3) and (P, T, 3), the body model's dtype.
    """
    P, T = observations.num_people, observations.num_frames
    points, valid = _observed_points_3d(observations)
    with torch.no_grad():
        zero = torch.zeros(P, 1, 3, dtype=body.dtype, device=body.device)
        reference = body.keypoints(rest, body.identity_pose(P, 1), zero)[:, 0].double().cpu()  # (P, 23, 3)
    index = [JOINT_INDEX[name] for name in _ROOT_POINTS]
    base = np.array(list(_ROOT_POINTS.values()))
    weights = valid[..., index] * base  # (P, T, K)
    usable = (valid[..., index].sum(-1) >= 3)
    source = reference[:, None, index].expand(P, T, len(index), 3)
    target = torch.from_numpy(points[..., index, :])
    safe = torch.from_numpy(np.where(usable[..., None], weights, base))
    R, t = roma.rigid_points_registration(source, target, weights=safe)
    R = _fill_invalid(R.numpy(), usable)
    t = _fill_invalid(t.numpy(), usable)
    to = dict(dtype=body.dtype, device=body.device)
    return torch.as_tensor(R, **to), torch.as_tensor(t, **to)


def _data_term(body: BodyModel, rest: RestSkeleton, observations: KeypointObservations,
               bone_rotmats: Tensor, translation: Tensor, cameras: tuple[Tensor, Tensor, Tensor] | None) -> tuple[Tensor, Tensor]:
    """Mean squared visible residual in units of the noise scale, and the keypoints (P, T, 23, 3)."""
    keypoints = body.keypoints(rest, bone_rotmats, translation)
    if cameras is None:
        residual = keypoints - observations.points
    else:
        K, R, t = cameras
        P, T, J, _ = keypoints.shape
        pixels, _, _ = project_points_torch(keypoints.reshape(1, P * T * J, 3), K, R, t)
        residual = pixels.reshape(-1, P, T, J, 2) - observations.points
    residual = torch.where(observations.visible.unsqueeze(-1), residual, torch.zeros_like(residual))
    count = observations.visible.sum().clamp(min=1) * residual.shape[-1]
    return (residual**2).sum() / count / observations.noise_scale**2, keypoints


def fit_motion(
    body: BodyModel,
    rest: RestSkeleton,
    observations: KeypointObservations,
    config: FitConfig,
    prior: MotionVAE | None = None,
) -> FitResult:
    """Fit the motions of P people to corrupted keypoints (module docstring).

    Args:
        body: the body model (fast keypoint path).
        rest: :meth:`BodyModel.rest_skeleton` of the P people (their known shapes).
        observations: the corrupted keypoints (3D, or 2D with cameras); tensors in the body model's dtype.
        config: weights and optimisation.
        prior: the motion VAE whose latents are fitted; None fits raw joint angles (no prior). Its weights are
            not changed.

    Returns:
        The :class:`FitResult`.

    Raises:
        ValueError: observations of another number of people than ``rest``, or another dtype than the body.
    """
    if observations.num_people != rest.num_people:
        raise ValueError(f"fit_motion: observations of {observations.num_people} people, rest skeleton of {rest.num_people}")
    if observations.points.dtype != body.dtype:
        raise ValueError(f"fit_motion: observations must be {body.dtype} like the body model, got {observations.points.dtype}")
    start = time.perf_counter()
    P, T = observations.num_people, observations.num_frames
    variables = _initial_variables(body, rest, observations, prior)
    cameras = _camera_tensors(observations, body) if observations.is_2d else None
    loss = _optimize(body, rest, observations, variables, cameras, config)
    with torch.no_grad():
        rotmats = variables.bone_rotmats()
        keypoints = body.keypoints(rest, rotmats, variables.translation)
    seconds = time.perf_counter() - start
    log.info("fit of %d x %d frames (%s): loss %.4f in %.1f s", P, T,
             "no prior" if prior is None else prior.config.variant, float(loss.detach()), seconds)
    return FitResult(
        bone_rotmats_local=rotmats.detach(),
        root_translation_m=variables.translation.detach(),
        keypoints_m=keypoints.detach(),
        latents=variables.body_params.detach() if prior is not None else None,
        final_loss=float(loss.detach()),
        seconds=seconds,
    )


@dataclass(frozen=True)
class _MotionVariables:
    """The variables of a motion fit (leaf tensors the optimiser moves in place), and how they pose the body.

    Attributes:
        root6d: (P, T, 6) root orientations (6D).
        translation: (P, T, 3) root translations, metres.
        body_params: (P, T, latent_dim) latent codes (prior fits), or (P, T, 21, 6) the bones' 6D rotations.
        identity: (P, T, 21, 6) the reference pose in 6D (where the no-prior fit's rest term pulls).
        prior: the motion VAE, in eval mode and without gradients of its own (None: the no-prior fit).
    """

    root6d: Tensor
    translation: Tensor
    body_params: Tensor
    identity: Tensor
    prior: MotionVAE | None

    def bone_rotmats(self) -> Tensor:
        """(P, T, 22, 3, 3) posed-bone rotations, root first (the latents decoded by the prior)."""
        six = self.prior.decode(self.body_params) if self.prior is not None else self.body_params
        return with_root(pose6d_to_rotmats(six), pose6d_to_rotmats(self.root6d))


def _initial_variables(body: BodyModel, rest: RestSkeleton, observations: KeypointObservations,
                       prior: MotionVAE | None) -> _MotionVariables:
    """The start: the root from a rigid fit of the reference pose (:func:`initial_root`), and the reference body
    pose (no-prior fit) or the prior's encoding of it (prior fits; the prior is moved to the body model's dtype and
    device, put in eval mode, and its weights frozen)."""
    P, T = observations.num_people, observations.num_frames
    to = dict(dtype=body.dtype, device=body.device)
    root_R, root_t = initial_root(body, rest, observations)
    root6d = rotmats_to_pose6d(root_R).clone().requires_grad_()
    translation = root_t.clone().requires_grad_()
    identity = identity_pose6d(**to).expand(P, T, NUM_PRIOR_BONES, 6)
    if prior is not None:
        prior = prior.to(**to).eval()
        prior.requires_grad_(False)
        with torch.no_grad():
            mu, _ = prior.encode(identity.contiguous())
        body_params = mu.clone().requires_grad_()
    else:
        body_params = identity.clone().requires_grad_()
    return _MotionVariables(root6d, translation, body_params, identity, prior)


def _camera_tensors(observations: KeypointObservations, body: BodyModel) -> tuple[Tensor, Tensor, Tensor]:
    """The V cameras of 2D observations as ``(K, R_cam_from_world, t_cam_from_world_m)``: (V, 3, 3), (V, 3, 3) and
    (V, 3) tensors in the body model's dtype and device."""
    to = dict(dtype=body.dtype, device=body.device)
    return tuple(torch.as_tensor(np.stack([getattr(c, name) for c in observations.cameras]), **to)
                 for name in ("K", "R_cam_from_world", "t_cam_from_world_m"))


def _objective(body: BodyModel, rest: RestSkeleton, observations: KeypointObservations, variables: _MotionVariables,
               cameras: tuple[Tensor, Tensor, Tensor] | None, config: FitConfig) -> Tensor:
    """The weighted objective (module docstring): the data term, the root's smoothness, and the latent
    regularizers (prior fits) or the decay toward the reference pose (no-prior fit)."""
    v = variables
    data, _ = _data_term(body, rest, observations, v.bone_rotmats(), v.translation, cameras)
    scale = config.root_smooth_scale_m
    root_smooth = (_mean_square(_second_difference(v.translation) / scale)
                   + _mean_square(_second_difference(v.root6d) / scale))
    loss = data + config.weight_root_smooth * root_smooth
    if v.prior is not None:
        loss = loss + config.weight_latent * _mean_square(v.body_params)
        loss = loss + config.weight_local_linear * _mean_square(_second_difference(v.body_params))
    else:
        loss = loss + config.weight_rest * _mean_square(v.body_params - v.identity)
    return loss


def _optimize(body: BodyModel, rest: RestSkeleton, observations: KeypointObservations, variables: _MotionVariables,
              cameras: tuple[Tensor, Tensor, Tensor] | None, config: FitConfig) -> Tensor:
    """Adam on the root and body pose, its learning rate decaying linearly to a tenth; the objective at the last
    step."""
    v = variables
    optimizer = torch.optim.Adam([v.root6d, v.translation, v.body_params], lr=config.learning_rate)
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda i: 1.0 - 0.9 * i / config.iterations)
    loss = torch.zeros(())
    for _ in range(config.iterations):
        optimizer.zero_grad(set_to_none=True)
        loss = _objective(body, rest, observations, variables, cameras, config)
        loss.backward()
        optimizer.step()
        schedule.step()
    return loss
