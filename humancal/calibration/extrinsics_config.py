"""Settings and results of :func:`humancal.calibration.extrinsics.estimate_extrinsics`: the configuration of every
step, the cameras, and what each step found along the way (per view, per view pair, the groups, the floor).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from humancal.calibration.floor import FloorAlignment
from humancal.calibration.lens import LensChoice
from humancal.calibration.view_agreement import AgreementConfig
from humancal.camera import CameraRig
from humancal.config import Config, at_least, in_range, positive

__all__ = ["ExtrinsicsConfig", "ExtrinsicsDiagnostics", "ExtrinsicsEstimate"]


@dataclass(frozen=True)
class ExtrinsicsConfig(Config):
    """Settings of :func:`estimate_extrinsics`.

    Attributes:
        rotation_threshold_deg: consensus radius of the pairwise rotation vote, degrees.
        max_pose_error_m: detection pairs whose aligned lifted poses differ more (RMS) are not the same person.
        max_frames_per_pair: shared frames used per view pair for the rotation vote (all views: at most
            ``max_pair_hypotheses`` pairs in total are kept by lowering it).
        max_pair_hypotheses: budget of detection pairs over all view pairs for the rotation vote.
        min_pair_support: a view pair needs this many supporting detections to be an edge.
        linear_iterations: passes of (root positions, linear focal + translation solve).
        linear_max_rel_std: a view whose linear focal has a larger data-only relative std is resected instead.
        single_view_min_rel_std: floor on the prior std of well-conditioned single-view focal lengths: a loose
            prior, so that the views' multi-view data decide and the single-view value mainly starts them
            (why 0.3: the CHANGELOG, "the stress sweep, three lifters").
        focal_range_rel: allowed focal range, multiples of the image diagonal (clips the initial values).
        max_groups: matched groups used by the bundle adjustment (spread over the sequence).
        shape_std_m: std of the lifted joints in the bundle adjustment, metres (chosen on seeded synthetic scenes
            with the shipped lifter, ``docs/results/calibration.md``).
        person_scale_std: relative std of a lifted person's size (a lifter sees body proportions, not size): the
            linear solve and the bundle adjustment estimate a size correction per matched pair / group with this
            prior, so that people's size errors do not distort the rig; None: sizes taken as lifted.
        bundle_iterations: Levenberg-Marquardt iterations.
        max_focal_rel_std: a final focal with a larger relative std is reported as ``poorly_constrained``.
        square_pixels: one focal per view (fx = fy).
        align_floor: move the result to the Z-up, floor z = 0 frame (else camera 0 stays the world).
        upright_threshold: groups whose reconstructed keypoints score at least this as standing
            (:func:`~humancal.lifter.standing_score`) count as standing for the floor.
        seed: randomness of the subsampling.
        fov_range_deg: plausible horizontal field of view (narrowest, widest), degrees: bounds every focal in the
            bundle adjustment (by its parameterization) and the focal a resection may start a view from.
        blind_start_fov_deg: views that neither a single view, the linear solve nor a resection could estimate
            start the bundle adjustment from the other views' field of view *and* from each of these diagonal
            fields of view (degrees; the diagonal makes them the same for portrait and landscape images), with
            translations solved again at those focal lengths; each start gets ``blind_start_iterations``
            iterations and the lowest cost goes on. Empty: the other views' field of view only.
        blind_start_iterations: bundle-adjustment iterations given to each start of the blind views.
        mismatch_threshold_sigma: after the bundle adjustment, a detection whose keypoints reproject further from
            its group's than this many keypoint stds (median; the std is 1 % of the person's image extent) is
            taken out of its group and the bundle adjustment run again (a person matched to a neighbour, the
            same way in every frame of a static scene, pulls the rig towards a wrong one); 0 turns this off.
        mismatch_max_fraction: when more of the detections than this fraction are above the threshold, none is
            taken out (the rig is off, not a few matches).
        mismatch_rounds: at most this many rounds of taking out and adjusting again.
        regroup_max_frames: after the first bundle adjustment, the detections of up to this many frames (spread
            evenly) are matched again with its cameras (:mod:`~humancal.calibration.regroup`: the association of
            the method, which finds the people the first, camera-free matching left out) and the bundle adjustment
            runs on those groups when they hold at least ``regroup_min_gain`` times the detections of the first
            ones (and more); 0 turns this off. Not with two views (see ``ExtrinsicsDiagnostics.regroup``).
        regroup_min_gain: see ``regroup_max_frames``.
        repair_views: after the bundle adjustment every view is scored by the people triangulated without it
            (:mod:`~humancal.calibration.view_agreement`); when on, the views that disagree are placed again
            against the people of the views that agree and the rig adjusted again
            (:mod:`~humancal.calibration.view_repair`); when off, they are only scored.
        scale_from_limbs: after the bundle adjustment, the world is scaled so that the people's median summed limb
            length is a reference adult's (:mod:`~humancal.calibration.world_scale`); off: the scale the lifted
            poses' sizes give.
        max_loo_sigma: a view disagrees when its keypoints reproject (median) more than this many keypoint stds
            (2 % of the person's image extent) from the people the other views triangulate.
        min_explained_fraction: a view disagrees when fewer of its detections than this fraction lie near a person
            the other views triangulate.
        lens_models: radial lens models compared on held-out frames after the bundle adjustment, simplest first
            (:mod:`~humancal.calibration.lens`): ``("pinhole",)`` turns radial distortion off, a single richer model
            is taken without comparison.
        principal_point: ``"auto"`` (estimated when held-out frames support it), ``"centre"`` (the image centre,
            or the known principal point) or ``"estimate"``.
        lens_min_gain: relative decrease of the held-out reprojection score a richer lens needs to be taken.
        lens_max_k1_std, lens_min_k1_sigma: a view keeps its estimated k1 only where its std is at most
            ``lens_max_k1_std`` and k1 lies at least ``lens_min_k1_sigma`` stds from 0; other views are pinholes.
    """

    rotation_threshold_deg: float = field(default=10.0, metadata=in_range(0, 90, low_open=True, high_open=True))
    max_pose_error_m: float = field(default=0.15, metadata=positive())
    max_frames_per_pair: int = 200
    max_pair_hypotheses: int = 150_000
    min_pair_support: int = 5
    linear_iterations: int = 6
    linear_max_rel_std: float = 0.15
    single_view_min_rel_std: float = 0.3
    focal_range_rel: tuple[float, float] = (0.15, 5.0)
    max_groups: int = field(default=200, metadata=at_least(3, integer=True))
    shape_std_m: float = field(default=0.5, metadata=positive())
    person_scale_std: float | None = field(default=0.1, metadata=positive(optional=True))
    bundle_iterations: int = 40
    max_focal_rel_std: float = field(default=0.05, metadata=positive())
    square_pixels: bool = True
    align_floor: bool = True
    upright_threshold: float = field(default=0.5, metadata=in_range(0, 1))
    seed: int = 0
    fov_range_deg: tuple[float, float] = (10.0, 140.0)
    blind_start_fov_deg: tuple[float, ...] = (50.0, 65.0, 80.0, 95.0, 115.0)
    blind_start_iterations: int = 12
    mismatch_threshold_sigma: float = field(default=10.0, metadata=at_least(0))
    mismatch_max_fraction: float = field(default=0.2, metadata=in_range(0, 1, low_open=True))
    mismatch_rounds: int = field(default=2, metadata=at_least(0, integer=True))
    regroup_max_frames: int = field(default=150, metadata=at_least(0, integer=True))
    regroup_min_gain: float = field(default=1.0, metadata=at_least(1))
    repair_views: bool = True
    scale_from_limbs: bool = True
    max_loo_sigma: float = field(default=3.0, metadata=positive())
    min_explained_fraction: float = field(default=0.75, metadata=in_range(0, 1))
    lens_models: tuple[str, ...] = ("k1",)
    principal_point: str = "centre"
    lens_min_gain: float = field(default=0.02, metadata=in_range(0, 1, high_open=True))
    lens_max_k1_std: float = field(default=0.25, metadata=positive())
    lens_min_k1_sigma: float = field(default=2.0, metadata=at_least(0))

    def agreement(self) -> AgreementConfig:
        """The thresholds of the views' agreement."""
        return AgreementConfig(max_loo_sigma=self.max_loo_sigma, min_explained=self.min_explained_fraction)

    def __post_init__(self) -> None:
        super().__post_init__()
        if not 0.0 < self.focal_range_rel[0] < self.focal_range_rel[1]:
            raise ValueError(f"ExtrinsicsConfig.focal_range_rel={self.focal_range_rel} must be 0 < low < high")
        if not 0.0 < self.fov_range_deg[0] < self.fov_range_deg[1] < 180.0:
            raise ValueError(f"ExtrinsicsConfig.fov_range_deg={self.fov_range_deg} must be 0 < narrowest < widest "
                             "< 180 degrees")
        if not self.lens_models or any(m not in ("pinhole", "k1", "k1k2") for m in self.lens_models):
            raise ValueError(f"ExtrinsicsConfig.lens_models={self.lens_models!r} must name one or more of 'pinhole', "
                             "'k1', 'k1k2' (simplest first)")
        if self.principal_point not in ("auto", "centre", "estimate"):
            raise ValueError(f"ExtrinsicsConfig.principal_point={self.principal_point!r} must be 'auto', 'centre' or "
                             "'estimate'")


@dataclass(frozen=True)
class ExtrinsicsDiagnostics:
    """What :func:`estimate_extrinsics` found along the way.

    Attributes:
        per_view: one row per view: ``view``, ``focal_single_view_px``, ``single_view_status``,
            ``focal_linear_px``, ``focal_px`` (final), ``focal_rel_std`` (final), ``focal_status`` (``"ok"`` or
            ``"poorly_constrained"``), ``focal_source`` (how the bundle adjustment was started:
            ``"single_view+bundle"`` (a well-conditioned single-view focal, also its prior), ``"linear+bundle"``,
            ``"resection+bundle"`` (recovered from the people placed by the other views) or
            ``"other_views+bundle"`` (neither the linear solve nor a resection gave a plausible focal: started
            from the other views' median field of view, left to the bundle adjustment)),
            ``bundle_status`` (``"ok"``, ``"focal_at_bound"``, ``"behind_camera"``, ``"no_inliers"``: see
            :class:`~humancal.calibration.bundle.BundleResult`; anything but ``"ok"`` makes the
            ``focal_status`` ``"poorly_constrained"``), ``reprojection_rms_px``, ``rotation_edges``, and the view's
            agreement with the others (:func:`~humancal.calibration.view_agreement.view_agreement`):
            ``agreement`` (``"ok"``, ``"disagrees"``, ``"unchecked"``), ``agreement_reason``, ``loo_error_sigma``,
            ``explained_fraction``, ``first_agreement`` (before any repair) and ``reregistered`` (placed again).
        pairs: one row per view pair: ``view_a``, ``view_b``, ``support``, ``residual_deg`` (disagreement of the
            pair rotation with the averaged rotations; NaN when unused).
        groups: the matched detections used: ``frame``, ``view``, ``det_id``, ``group``.
        floor: the :class:`FloorAlignment` (None when ``align_floor`` is off or no floor was found).
        world_frame: ``"floor"`` (Z up, floor at z = 0, origin on the floor amid the people) or ``"camera_0"``
            (camera 0 at the origin looking along +z, OpenCV axes: ``align_floor`` off, or no floor found).
        floor_problem: why no floor was found (None when one was, or when not asked for).
        people_world_m: (G, 3) the matched groups' hip midpoints in the returned world frame, metres.
        body_size_ratio: median over the groups of their triangulated limb lengths over their lifted ones (the
            lifter sees body proportions and sizes the people): about 1 for a consistent rig; far from 1, the
            cameras and the people disagree (a wrong solution, whatever its reprojection error).
        bundle_inlier_fraction: keypoints within the Huber threshold in the bundle adjustment.
        mismatched_detections: detections taken out of their groups after a bundle adjustment (reprojected over
            ``mismatch_threshold_sigma`` stds away: matched to the wrong person); ``groups`` is without them.
        regroup: ``"regrouped"`` (the groups were found again with the first bundle adjustment's cameras, and
            ``groups`` are those), ``"kept: too few more detections"``, ``"kept: association failed"`` (logged), or
            ``"off"`` (``regroup_max_frames`` 0) or ``"off: two views"`` (with two views the camera-free
            matching's groups are kept: geometry adds one epipolar line, which a wrong pair near it passes).
        regroup_detections: detections in the first groups and in the groups found again (both after choosing at
            most ``max_groups``; (0, 0) when off).
        scale_factor: the factor the world was scaled by after the bundle adjustment so that the people have a
            reference adult's limbs (1: ``scale_from_limbs`` off, or too few people with all limbs).
        lens: the lens chosen on held-out frames (:class:`~humancal.calibration.lens.LensChoice`; None for known
            cameras used as given). ``per_view`` then has each view's ``k1``, ``k1_std`` (NaN: kept a pinhole),
            ``k2``, ``cx_px``, ``cy_px``, ``cx_std_px`` and ``cy_std_px`` (NaN: kept at the centre).
        timings_s: seconds per step.
    """

    per_view: pd.DataFrame
    pairs: pd.DataFrame
    groups: pd.DataFrame
    floor: FloorAlignment | None
    bundle_inlier_fraction: float
    timings_s: dict[str, float] = field(default_factory=dict)
    world_frame: str = "floor"
    floor_problem: str | None = None
    people_world_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    body_size_ratio: float = float("nan")
    mismatched_detections: int = 0
    regroup: str = "off"
    regroup_detections: tuple[int, int] = (0, 0)
    scale_factor: float = 1.0
    lens: LensChoice | None = None


@dataclass(frozen=True)
class ExtrinsicsEstimate:
    """Calibrated cameras (intrinsics refined by the multi-view step) and diagnostics."""

    cameras: CameraRig
    diagnostics: ExtrinsicsDiagnostics
