"""The model of the simulated 2D pose detector's errors (:class:`DetectorNoise`), a field of
:class:`humancal.synthetic.config.SceneConfig`; :mod:`humancal.synthetic.noise` applies it.

A frozen dataclass validated on construction: a bad value raises a one-line ``ValueError`` naming the field, the value
received and the allowed range.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from humancal.config import Config, in_range

__all__ = ["DetectorNoise"]


@dataclass(frozen=True)
class DetectorNoise(Config):
    """How the simulated 2D pose detector errs (``docs/synthetic.md``, "Noise model").

    Image-space spreads scale with the person's apparent height ``scale_px = fx * height_m / depth_m`` (pelvis
    depth), so a far person gets proportionally smaller pixel errors, like a real detector working on a
    resized crop. Per-joint spreads follow the COCO keypoint sigmas (hips noisier than eyes), normalised to a
    mean weight of 1 over the 23 joints.

    Attributes:
        jitter_std_frac: std of the Gaussian jitter per image axis, as a fraction of ``scale_px`` (mean over
            joints). 0.008 is about 3 px on a 400 px tall person.
        occluded_jitter_factor: multiplies the jitter of a fully occluded joint (>= 1; partial occlusion
            interpolates).
        outlier_rate: probability that a detected joint is a gross outlier (in [0, 1]).
        outlier_std_frac: std of an outlier's extra offset per axis, fraction of ``scale_px``.
        score_mean: mean confidence of a clearly visible joint, in [0, 1].
        score_std: std of the per-joint confidence noise.
        occlusion_score_drop: confidence lost by a fully occluded joint.
        border_margin_frac: width of the band inside the image border where confidence falls, fraction of
            ``scale_px``.
        border_score_drop: confidence lost by a joint right at the image border.
        joint_miss_rate: probability that a visible, unoccluded joint is missing from its detection.
        occluded_joint_miss_rate: probability that a fully occluded joint is missing (partial occlusion
            interpolates between the two rates).
        person_miss_rate: probability that a person in view gives no detection at all in a view and frame.
        min_visible_joints: a person gives a detection only with at least this many joints inside the image
            and not fully occluded (1..23).
        false_positives_per_image: mean number of false-positive detections per view and frame (Poisson).
        false_positive_fragment_prob: probability that a false positive is a fragment (one body part) rather
            than a whole skeleton.
        false_positive_score_mean: mean joint confidence of a false positive, in [0, 1].
        flip_rate: probability that a detection has its left and right labels swapped.
        keypoint_bias_m: std per axis of each keypoint's systematic offset from the body model's keypoint, metres
            (0: none). A real detector is trained on its own definition of the joints (where a hip or an ankle
            is); the offsets are drawn once per scene, in the axes of the keypoint's dominant bone, the same for
            every person and frame, and mirrored between left and right
            (:func:`humancal.synthetic.noise.draw_keypoint_bias`). The ground truth keeps the model's keypoints.
    """

    jitter_std_frac: float = field(default=0.008, metadata=in_range(0, 1))
    occluded_jitter_factor: float = field(default=3.0, metadata=in_range(1, 100))
    outlier_rate: float = field(default=0.005, metadata=in_range(0, 1))
    outlier_std_frac: float = field(default=0.08, metadata=in_range(0, 1))
    score_mean: float = field(default=0.85, metadata=in_range(0, 1))
    score_std: float = field(default=0.06, metadata=in_range(0, 1))
    occlusion_score_drop: float = field(default=0.5, metadata=in_range(0, 1))
    border_margin_frac: float = field(default=0.05, metadata=in_range(0, 1))
    border_score_drop: float = field(default=0.3, metadata=in_range(0, 1))
    joint_miss_rate: float = field(default=0.02, metadata=in_range(0, 1))
    occluded_joint_miss_rate: float = field(default=0.5, metadata=in_range(0, 1))
    person_miss_rate: float = field(default=0.03, metadata=in_range(0, 1))
    min_visible_joints: int = field(default=4, metadata=in_range(1, 23, integer=True))
    false_positives_per_image: float = field(default=0.05, metadata=in_range(0, 20))
    false_positive_fragment_prob: float = field(default=0.5, metadata=in_range(0, 1))
    false_positive_score_mean: float = field(default=0.4, metadata=in_range(0, 1))
    flip_rate: float = field(default=0.02, metadata=in_range(0, 1))
    keypoint_bias_m: float = field(default=0.0, metadata=in_range(0, 0.2))

    @classmethod
    def none(cls) -> DetectorNoise:
        """A perfect detector: exact projections, confidence 1, nothing missed, no false positives or flips.

        Joints outside the image are still dropped, and a person needs one joint in the image to be detected.
        """
        return cls(
            jitter_std_frac=0.0,
            occluded_jitter_factor=1.0,
            outlier_rate=0.0,
            score_mean=1.0,
            score_std=0.0,
            occlusion_score_drop=0.0,
            border_score_drop=0.0,
            joint_miss_rate=0.0,
            occluded_joint_miss_rate=0.0,
            person_miss_rate=0.0,
            min_visible_joints=1,
            false_positives_per_image=0.0,
            flip_rate=0.0,
        )
