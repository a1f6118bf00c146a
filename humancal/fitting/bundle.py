"""Bundle adjustment of the cameras on the triangulated keypoints: the start of the joint refinement
(``BodyFitConfig.bundle_start``) and, followed by bodies with these cameras held, the paper's "separate" baseline.

The cameras are refined first, on their own, against free 3D points (the association's triangulated joints,
one point per person, frame and keypoint) and the same confidence-weighted Geman-McClure reprojection as the body
fit; the bodies are then fitted with these cameras held. Unlike the joint refinement, nothing ties the points to a
body (bone lengths, a plausible pose, smooth motion), which is what the comparison measures.

Points and cameras move together (L-BFGS, one problem); the similarity that moves both at once is fixed by the
weak tie of each camera to its initial value (``BodyFitConfig.weight_camera_prior``). It runs in torch with the
fit's own camera parametrisation and robust cost, so the two regimes differ only in what the cameras are
refined against.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from humancal.camera import CameraRig
from humancal.fitting.cameras import CameraVariables
from humancal.fitting.config import BodyFitConfig
from humancal.fitting.observations import BodyObservations, FittingInputError

__all__ = ["BundleResult", "bundle_adjust"]


@dataclass(frozen=True)
class BundleResult:
    """A bundle adjustment's output.

    Attributes:
        cameras: the refined cameras.
        points_world_m: (P, T, 23, 3) the refined points (NaN where no triangulated joint was given).
        reprojection_error_px: mean pixel distance of the refined points to their detections (confident ones).
        seconds: wall time.
        failure: why the adjustment was undone (its objective became non-finite: the cameras and points are then
            the initial ones), else None.
    """

    cameras: CameraRig
    points_world_m: np.ndarray
    reprojection_error_px: float
    seconds: float
    failure: str | None = None


def bundle_adjust(observations: BodyObservations, rig: CameraRig, config: BodyFitConfig = BodyFitConfig(), *,
                  regime: str = "int_ext", iterations: int = 100, dtype: torch.dtype = torch.float64
                  ) -> BundleResult:
    """Refine the cameras (``regime``: ``ext`` or ``int_ext``) and the triangulated joints on the detections.

    Args:
        observations: the people's detections and triangulated joints (:func:`body_observations`).
        rig: the V initial cameras.
        config: the robust scales and the camera tie (``noise_px``, ``robust_scale_px``, ``weight_camera_prior``,
            ``camera_prior_scale_m``, ``refine_k1``).
        regime: which camera parameters move (``humancal.fitting.cameras``).
        iterations: L-BFGS iterations.

    Raises:
        FittingInputError: the views do not match the rig, or there is no confident detection of a valid joint.
    """
    if observations.num_views != len(rig):
        raise FittingInputError(f"bundle adjustment: detections of {observations.num_views} views, but {len(rig)} "
                                "cameras")
    start = time.perf_counter()
    cams = CameraVariables(rig, regime, refine_k1=config.refine_k1, dtype=dtype)
    valid = torch.as_tensor(observations.joints_valid)
    points = torch.as_tensor(observations.joints_world_m, dtype=dtype).clone()
    observed = torch.as_tensor(observations.keypoints_px, dtype=dtype)
    weights = torch.as_tensor(observations.confidence, dtype=dtype) * valid.to(dtype)
    if not (weights > 0).any():
        raise FittingInputError("bundle adjustment: no confident detection of a triangulated joint")
    free = points[valid].clone().requires_grad_()
    centre0 = cams.centre_m.detach().clone()
    s2, n2 = config.robust_scale_px**2, config.noise_px**2

    def residuals() -> tuple[torch.Tensor, torch.Tensor]:
        full = points.clone()
        full[valid] = free
        pixels, _, in_front = cams.tensors().project(full.reshape(-1, 3))
        r2 = ((pixels.reshape(observed.shape) - observed) ** 2).sum(-1)
        return r2, weights * in_front.reshape(r2.shape).to(dtype)

    def objective() -> torch.Tensor:
        r2, w = residuals()
        data = (s2 * r2 / (r2 + s2) / n2 * w).sum() / w.sum()
        tie = (cams.log_focal**2).mean() + (cams.rotvec**2).mean() + \
            (((cams.centre_m - centre0) / config.camera_prior_scale_m) ** 2).mean()
        return data + config.weight_camera_prior * tie

    optimizer = torch.optim.LBFGS([*cams.variables(), free], lr=1.0, max_iter=iterations, history_size=10,
                                  line_search_fn="strong_wolfe", tolerance_grad=1e-9, tolerance_change=1e-12)

    def closure() -> torch.Tensor:
        optimizer.zero_grad(set_to_none=True)
        loss = objective()
        if not torch.isfinite(loss):
            raise FloatingPointError(f"bundle adjustment: the objective became {loss.item()}")
        loss.backward()
        return loss

    variables = [*cams.variables(), free]
    snapshot = [v.detach().clone() for v in variables]
    failure = None
    try:
        optimizer.step(closure)
    except FloatingPointError as error:  # back to the start: never a rig of non-finite cameras
        failure = f"{error}; the initial cameras were kept"
        with torch.no_grad():
            for variable, saved in zip(variables, snapshot):
                variable.copy_(saved)
    with torch.no_grad():
        r2, w = residuals()
        error = float(r2[w > 0].sqrt().mean())
        out = torch.full_like(points, float("nan"))
        out[valid] = free
    return BundleResult(cams.to_rig(), out.numpy(), error, time.perf_counter() - start, failure)
