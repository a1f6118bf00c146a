"""Settings of the body fit (:func:`humancal.fitting.fit_bodies`): weights, robust scales, windows, iterations."""

from __future__ import annotations

from dataclasses import dataclass, field

from humancal.config import Config, at_least, in_range, positive

__all__ = ["BodyFitConfig"]

_CHOICE_FIELDS = {"cameras": ("fixed", "ext", "int_ext"),  # humancal.fitting.cameras.CAMERA_REGIMES
                  "latent_start": ("prior_mean", "reference_pose"),
                  "bundle_solver": ("lm", "lbfgs")}
_BOOL_FIELDS = ("fit_shape", "refine_k1", "unswap_left_right", "bundle_start")


@dataclass(frozen=True)
class BodyFitConfig(Config):
    """Weights and schedule of a body fit.

    The data terms are Geman-McClure robust costs in units of the expected noise: a residual ``r`` costs
    ``rho(r) = s^2 r^2 / (r^2 + s^2) / n^2`` with ``s`` the robust scale and ``n`` the noise scale, so small
    residuals cost ``(r / n)^2`` (least squares in units of the noise) and an outlier at most ``(s / n)^2``.
    Each term is a mean (data: over confident observations, weighted by confidence; priors: over their entries),
    so weights do not change with the number of people, frames or views.

    Attributes:
        noise_px: expected 2D keypoint noise, pixels.
        robust_scale_px: Geman-McClure scale of the reprojection term, pixels.
        noise_3d_m: expected noise of the triangulated joints (the 3D initialisation stage), metres.
        robust_scale_3d_m: Geman-McClure scale of the 3D stage, metres.
        weight_latent: weight of ``mean(z^2)`` (the prior's N(0, I)).
        weight_local_linear: weight of the mean squared latent second difference (the paper's local-linear term)
            in the stages on the 2D detections.
        weight_local_linear_3d: the same in the first stage, on the triangulated joints (a stiff temporal term slows
            that stage's Adam steps; the L-BFGS stages after it cope with a stiffer one).
        weight_rest: weight of the mean squared 6D offset from the reference pose (the no-prior fit only).
        weight_shape: weight of the mean squared phenotype change from the initial (average adult) body.
        weight_root_smooth: weight of the root's mean squared second difference (translation in units of
            ``root_smooth_scale_m``; 6D orientation in units of ``root_smooth_scale_m`` per metre).
        root_smooth_scale_m: the root's expected second difference, metres per frame^2.
        weight_seam: weight of the mean squared 6D difference of two windows' decodings of the same frame.
        window_frames: frames of one latent window (long sequences are cut into overlapping windows that are
            decoded as one batch; a sequence no longer than this is one window).
        window_overlap: frames shared by consecutive windows.
        latent_start: where a prior fit's latents start: ``prior_mean`` (z = 0, the prior's mode: a natural
            average pose) or ``reference_pose`` (the encoding of the body model's reference pose, arms out).
        iterations_3d: Adam steps of the initialisation stage on the triangulated joints (shape, root, pose).
        half_rate_fraction_3d: the fraction of those steps that run first on every other frame (the sequence at
            half its frame rate: half the frames to decode per step, and a motion the prior knows, since it is
            trained on clips played at half to twice their speed); the fitted variables are then interpolated to
            every frame and the rest of the steps run there. Only for sequences of at least ``2 * window_frames``
            frames (shorter ones are cheap). 0: every step on every frame.
        learning_rate_3d: Adam's initial learning rate there (decays linearly to a tenth over all the steps).
        iterations_global: L-BFGS iterations of the global stage (root orientation and translation on the 2D
            detections, pose and shape held).
        iterations_body: L-BFGS iterations of the body stage (everything on the 2D detections).
        fit_shape: whether the phenotypes are fitted (else the average adult body).
        cameras: which camera parameters move (``humancal.fitting.cameras``): ``fixed``, ``ext`` (extrinsics) or
            ``int_ext`` (focal length and extrinsics: fully self-calibrated).
        refine_k1: whether each view's first radial distortion coefficient moves too (with ``ext``/``int_ext``).
        bundle_start: whether moving cameras (``ext``, ``int_ext``) first take a bundle adjustment on the
            triangulated joints as free points (:func:`humancal.fitting.joint_bundle.bundle_adjust_on_joints`,
            regime ``cameras``) before the joint refinement starts from them. Free points take up a detector's own
            definition of the joints, which the bodies cannot (``docs/refinement.md``, "A detector with its own
            joints").
        bundle_solver: how that bundle adjustment is solved (``humancal.fitting.joint_bundle``): ``lm``
            (Levenberg-Marquardt with the points eliminated, run to convergence) or ``lbfgs`` (100 L-BFGS
            iterations, which stop short of the minimum; ``docs/results/refinement.md``).
        bundle_max_frames: that bundle adjustment uses every k-th frame, k = max(1, T // bundle_max_frames), so at
            most ``2 * bundle_max_frames - 1`` frames (the cameras are static: a few hundred frames fix them, and
            the solve costs in proportion to the frames).
        rounds: how many times the three substages on the 2D detections (cameras, global, body) run in turn
            (with ``fixed`` cameras, the camera substage is skipped).
        round_stop_px: the rounds end early after a round whose camera substage moved the cameras less than this:
            the mean distance, pixels, between the fitted keypoints projected through every view before and after
            that substage (:func:`humancal.fitting.cameras.camera_shift_px`); 0: always ``rounds`` rounds.
        iterations_cameras: L-BFGS iterations of the camera substage (bodies held).
        weight_camera_prior: weight of the mean squared camera change from the initial cameras (focal in log
            units, rotation in radians, centre in units of ``camera_prior_scale_m``); a weak tie that keeps views
            with few observations in place.
        camera_prior_scale_m: the camera centre change that costs as much as a unit log-focal change, metres.
        weight_interpenetration: weight of the sphere-proxy interpenetration penalty between people
            (``humancal.fitting.contact``; squared overlap depth in units of ``contact_scale_m``).
        contact_scale_m: the overlap depth that costs one unit, metres.
        unswap_left_right: whether detections whose left and right joints the detector swapped are swapped back
            before the fit (:func:`humancal.fitting.observations.unswap_left_right`, against the triangulated
            joints through the initial cameras; ``noise_px`` is the error below which a detection is left alone).
    """

    noise_px: float = field(default=15.0, metadata=positive())
    robust_scale_px: float = field(default=40.0, metadata=positive())
    noise_3d_m: float = field(default=0.03, metadata=positive())
    robust_scale_3d_m: float = field(default=0.15, metadata=positive())
    weight_latent: float = field(default=1e-3, metadata=at_least(0))
    weight_local_linear: float = field(default=100.0, metadata=at_least(0))
    weight_local_linear_3d: float = field(default=100.0, metadata=at_least(0))
    weight_rest: float = field(default=1e-4, metadata=at_least(0))
    weight_shape: float = field(default=1e-2, metadata=at_least(0))
    weight_root_smooth: float = field(default=0.1, metadata=at_least(0))
    root_smooth_scale_m: float = field(default=0.01, metadata=positive())
    weight_seam: float = field(default=100.0, metadata=at_least(0))
    window_frames: int = field(default=32, metadata=at_least(4, integer=True))
    window_overlap: int = field(default=6, metadata=at_least(0, integer=True))
    latent_start: str = "prior_mean"
    iterations_3d: int = field(default=300, metadata=at_least(0, integer=True))
    half_rate_fraction_3d: float = field(default=0.8, metadata=in_range(0, 1))
    iterations_global: int = field(default=10, metadata=at_least(0, integer=True))
    iterations_body: int = field(default=20, metadata=at_least(0, integer=True))
    learning_rate_3d: float = field(default=0.05, metadata=positive())
    fit_shape: bool = True
    cameras: str = "int_ext"
    refine_k1: bool = False
    bundle_start: bool = True
    bundle_solver: str = "lm"
    bundle_max_frames: int = field(default=300, metadata=at_least(1, integer=True))
    rounds: int = field(default=3, metadata=at_least(0, integer=True))
    round_stop_px: float = field(default=0.0, metadata=at_least(0))
    iterations_cameras: int = field(default=50, metadata=at_least(0, integer=True))
    weight_camera_prior: float = field(default=1e-6, metadata=at_least(0))
    camera_prior_scale_m: float = field(default=0.1, metadata=positive())
    weight_interpenetration: float = field(default=0.0, metadata=at_least(0))
    contact_scale_m: float = field(default=0.01, metadata=positive())
    unswap_left_right: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        for name, choices in _CHOICE_FIELDS.items():
            if getattr(self, name) not in choices:
                raise ValueError(f"BodyFitConfig.{name}={getattr(self, name)!r} must be one of {list(choices)}")
        for name in _BOOL_FIELDS:
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"BodyFitConfig.{name}={getattr(self, name)!r} must be True or False")
        if not self.window_overlap < self.window_frames // 2:
            raise ValueError(f"BodyFitConfig: window_frames={self.window_frames} must be >= 4 and window_overlap="
                             f"{self.window_overlap} in [0, window_frames / 2)")
