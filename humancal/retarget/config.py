"""Settings of the mocap retarget (one frozen dataclass; no global dicts)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from humancal.config import Config, at_least, positive
from humancal.retarget.correspondence import DAZ_CMU_LINKS, JointLink

__all__ = ["RetargetConfig"]


@dataclass(frozen=True)
class RetargetConfig(Config):
    """How mocap is retargeted onto the body model (``docs/retarget.md``).

    Weights are relative to the data term, the weighted sum over mapped points of squared distances in m^2,
    averaged over frames; rotation penalties use the squared Frobenius norm of a 3x3 difference
    (``||R - I||_F^2 = 8 sin^2(angle / 2)``, about 2 angle^2 for small angles in radians).

    Attributes:
        fps: clips are resampled to this frame rate (frames per second) before the fit.
        links: the joint correspondence table (:data:`humancal.retarget.DAZ_CMU_LINKS` by default).
        shape_frames: frames per subject used by the shape fit, spread evenly over all of its clips.
        length_iterations: L-BFGS iterations of the bone-length stage of the shape fit.
        joint_iterations: the most Gauss-Newton iterations of each joint solve of the shape frames' poses and the
            offsets (:mod:`humancal.retarget.offsets`).
        shape_rounds: alternations of an L-BFGS solve over phenotypes and offsets (poses fixed) and a joint poses +
            offsets solve.
        shape_iterations: L-BFGS iterations of each such solve.
        phenotype_init: starting phenotypes, ``PHENOTYPE_NAMES`` order, in [0, 1] (and within the bounds).
        phenotype_low: lower bound of each phenotype (the fit maps a sigmoid onto [low, high]).
        phenotype_high: upper bound of each phenotype. The default keeps age adult (>= 0.5, teenager).
        phenotype_prior_weight: squared distance of the phenotypes to ``phenotype_init`` (per unit^2); it
            resolves the phenotypes that bone lengths do not determine (gender, muscle, weight).
        offset_prior_weight: squared length of the learned ``"along"`` offsets (per m^2); keeps the shifts of
            joints along the anny segments to what the data demands.
        free_offset_prior_weight: squared norm of the learned ``"free"`` offsets (per m^2). Much weaker than the
            pose prior's say on the constant rotation these offsets can trade with (the chain ends', the pelvis
            pitch), so that the priors set those to the least rotation on average (e.g. a level head, not a head
            nodding down to reach eyes that sit lower in the mocap skeleton), not to the smallest offset.
        pose_prior_weight: ``||D_b - I||_F^2`` summed over the non-root bones, per frame (m^2 per unit). Small:
            it only decides what no mapped point observes (forearm and shin twist, toes, the split of a bend
            between the spine bones).
        bone_prior_scale: ``(bone, factor)`` pairs multiplying ``pose_prior_weight`` for some bones. The default
            makes the clavicles 10x stiffer: the points cannot tell a clavicle's turn about its own axis from
            the upper arm's, and an even split (the plain prior's choice) put half of every arm raise into the
            clavicles.
        hinge_bones: bones that bend in one plane (knees, elbows; the flexion axis ``a`` and rest direction ``d``
            from the rest skeleton, ``humancal.retarget.priors.PoseWeights.from_config``); they may still twist
            about their own axis.
        hinge_prior_weight: weight of ``(a . D d)^2`` per hinge and frame (m^2 per unit), the squared sine of how
            far the bone leaves its flexion plane (bends sideways). The points fix where a forearm points, not
            whether the upper arm is twisted and the elbow bent sideways or the elbow bent in its plane; this
            term (100x the pose prior) picks the anatomical one.
        pelvis_tilt_prior_weight: in the shape fit only, weight of the squared sine of the pelvis' tilt from
            upright, per frame. With free offsets on the pelvis points, the constant part of the pelvis' rotation
            is open; this makes the pelvis level on average over the shape frames (rather than tilted 15-20 deg
            back with the lumbar spine bent forward, the plain pose prior's choice). The clip fits have the
            offsets fixed and follow the mocap pelvis frame by frame.
        smooth_weight: ``||D_b(t) - D_b(t-1)||_F^2`` over every bone plus ``||t(t) - t(t-1)||^2`` (m^2),
            per frame.
        chunk_frames: the pose fit solves this many consecutive frames together (memory grows with it).
        pose_iterations: the most Levenberg-Marquardt iterations of the pose fit (it stops earlier once no frame
            improves beyond round-off).
        lbfgs_history: L-BFGS history size (shape fit).
        init_child_weight: in the analytic initialisation, weight of the points of a bone's children (relative to
            their link weight) when the bone's own points do not spread in two directions (fixes the twist of a
            limb from the next joint, the pitch of the pelvis).
        torch_threads: torch intra-op threads while fitting (set for the call, restored after); ``None`` leaves
            torch's setting alone. One is fastest for these many small batched solves: two threads made a
            subject's fit 11x slower on the 2-core development machine under load (``humancal.retarget.threads``).
    """

    fps: float = field(default=30.0, metadata=positive())
    links: tuple[JointLink, ...] = DAZ_CMU_LINKS
    shape_frames: int = field(default=96, metadata=positive(integer=True))
    length_iterations: int = field(default=20, metadata=positive(integer=True))
    joint_iterations: int = field(default=15, metadata=positive(integer=True))
    shape_rounds: int = field(default=2, metadata=at_least(0, integer=True))
    shape_iterations: int = field(default=20, metadata=positive(integer=True))
    phenotype_init: tuple[float, ...] = (0.5, 2.0 / 3.0, 0.5, 0.5, 0.3, 0.5)
    phenotype_low: tuple[float, ...] = (0.0, 0.5, 0.0, 0.0, 0.0, 0.0)
    phenotype_high: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    phenotype_prior_weight: float = field(default=1e-4, metadata=at_least(0))
    offset_prior_weight: float = field(default=1e-2, metadata=at_least(0))
    free_offset_prior_weight: float = field(default=1e-5, metadata=at_least(0))
    pose_prior_weight: float = field(default=1e-5, metadata=at_least(0))
    bone_prior_scale: tuple[tuple[str, float], ...] = (("clavicle.L", 10.0), ("clavicle.R", 10.0))
    hinge_bones: tuple[str, ...] = ("lowerleg01.L", "lowerleg01.R", "lowerarm01.L", "lowerarm01.R")
    hinge_prior_weight: float = field(default=1e-3, metadata=at_least(0))
    pelvis_tilt_prior_weight: float = field(default=1e-3, metadata=at_least(0))
    smooth_weight: float = field(default=1e-4, metadata=at_least(0))
    chunk_frames: int = field(default=512, metadata=positive(integer=True))
    pose_iterations: int = field(default=4, metadata=positive(integer=True))
    lbfgs_history: int = field(default=20, metadata=positive(integer=True))
    init_child_weight: float = field(default=0.25, metadata=at_least(0))
    torch_threads: int | None = field(default=1, metadata=positive(integer=True, optional=True))

    def __post_init__(self) -> None:
        super().__post_init__()
        for item in self.bone_prior_scale:
            if len(item) != 2 or not isinstance(item[0], str) or not item[1] >= 0:
                raise ValueError(f"RetargetConfig.bone_prior_scale needs (bone name, factor >= 0) pairs, got {item!r}")
        for name in ("phenotype_init", "phenotype_low", "phenotype_high"):
            if len(getattr(self, name)) != 6:
                raise ValueError(
                    f"RetargetConfig.{name} must hold 6 values (PHENOTYPE_NAMES), got {getattr(self, name)!r}"
                )
        for i, (low, init, high) in enumerate(zip(self.phenotype_low, self.phenotype_init, self.phenotype_high)):
            if not 0.0 <= low < high <= 1.0 or not low <= init <= high:
                raise ValueError(
                    f"RetargetConfig phenotype {i}: need 0 <= low < high <= 1 and low <= init <= high, "
                    f"got low={low}, init={init}, high={high}"
                )

    @classmethod
    def tiny(cls) -> "RetargetConfig":
        """A fast preset for tests and smoke runs (fewer shape frames and iterations)."""
        return cls(shape_frames=24, length_iterations=15, joint_iterations=10, shape_rounds=1, shape_iterations=15,
                   chunk_frames=64, pose_iterations=4)

    def with_links(self, links: tuple[JointLink, ...]) -> "RetargetConfig":
        """The same settings with another correspondence table."""
        return replace(self, links=tuple(links))
