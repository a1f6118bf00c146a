"""Retarget mocap clips onto the body model: per subject a shape, per frame a pose (``docs/retarget.md``)."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from humancal.body import PHENOTYPE_NAMES, BodyModel
from humancal.keypoints import NUM_JOINTS
from humancal.mocap import MocapClip, read_bvh
from humancal.retarget.config import RetargetConfig
from humancal.retarget.correspondence import mocap_targets_m, resolve_links
from humancal.retarget.points import PointModel
from humancal.retarget.pose import fit_poses
from humancal.retarget.shape import SubjectFit, check_phenotypes, fit_subject
from humancal.retarget.threads import torch_threads

__all__ = ["RetargetedClip", "retarget_clip", "retarget_clips"]

logger = logging.getLogger(__name__)

NUM_POSED_BONES = 22


def _frozen_array(value, shape: tuple[int | None, ...], name: str, clip: str) -> np.ndarray:
    array = np.array(value, dtype=np.float64, copy=True)
    if array.ndim != len(shape) or any(want is not None and got != want for got, want in zip(array.shape, shape)):
        spelled = "(" + ", ".join("F" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"RetargetedClip {clip!r}: {name} must have shape {spelled}, got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"RetargetedClip {clip!r}: {name} holds non-finite values")
    array.setflags(write=False)
    return array


@dataclass(frozen=True)
class RetargetedClip:
    """A mocap clip as body-model parameters, with what the body model then predicts and how well it matches.

    Arrays are read-only float64. World frame of ``docs/conventions.md`` (metres, Z up, floor z = 0).

    Attributes:
        name: clip name, e.g. ``"02_01"``.
        subject: subject id, e.g. ``"02"``.
        fps: frame rate of every per-frame array.
        phenotypes: (6,) in [0, 1], ``PHENOTYPE_NAMES`` order (one shape per subject).
        bone_rotmats_local: (F, 22, 3, 3) anny "local-ref" rotations of the posed bones (``docs/body_model.md``).
        root_translation_m: (F, 3) world position of the root bone head, metres.
        keypoints_world_m: (F, 23, 3) the canonical keypoints of the posed body model, metres.
        joints_world_m: (F, 22, 3) posed-bone heads, metres; ``None`` for a clip rebuilt from a motions table
            without a body model.
        residual_mm: (F, M) distance of each mapped body-model point to its mocap joint, mm ((F, 0) when unknown).
        mapped_joint_names: (M,) the mocap joints of the correspondence, in ``residual_mm`` column order.
        offsets_m: (M, 3) the subject's learned correspondence offsets, metres ((0, 3) when unknown).
    """

    name: str
    subject: str
    fps: float
    phenotypes: np.ndarray
    bone_rotmats_local: np.ndarray
    root_translation_m: np.ndarray
    keypoints_world_m: np.ndarray
    joints_world_m: np.ndarray | None
    residual_mm: np.ndarray
    mapped_joint_names: tuple[str, ...]
    offsets_m: np.ndarray

    def __post_init__(self) -> None:
        name = str(self.name)
        rotmats = _frozen_array(self.bone_rotmats_local, (None, NUM_POSED_BONES, 3, 3), "bone_rotmats_local", name)
        frames = rotmats.shape[0]
        if frames < 1:
            raise ValueError(f"RetargetedClip {name!r}: needs at least one frame")
        mapped = tuple(str(n) for n in self.mapped_joint_names)
        set_ = object.__setattr__
        set_(self, "bone_rotmats_local", rotmats)
        set_(self, "phenotypes", _frozen_array(self.phenotypes, (len(PHENOTYPE_NAMES),), "phenotypes", name))
        if (self.phenotypes < 0).any() or (self.phenotypes > 1).any():
            raise ValueError(f"RetargetedClip {name!r}: phenotypes must lie in [0, 1], got {self.phenotypes.tolist()}")
        for field, shape in (("root_translation_m", (frames, 3)), ("keypoints_world_m", (frames, NUM_JOINTS, 3))):
            set_(self, field, _frozen_array(getattr(self, field), shape, field, name))
        if self.joints_world_m is not None:
            joints = _frozen_array(self.joints_world_m, (frames, NUM_POSED_BONES, 3), "joints_world_m", name)
            set_(self, "joints_world_m", joints)
        set_(self, "residual_mm", _frozen_array(self.residual_mm, (frames, len(mapped)), "residual_mm", name))
        set_(self, "offsets_m", _frozen_array(self.offsets_m, (len(mapped), 3), "offsets_m", name))
        set_(self, "mapped_joint_names", mapped)
        set_(self, "name", name)
        set_(self, "subject", str(self.subject))
        fps = float(self.fps)
        if not (np.isfinite(fps) and fps > 0):
            raise ValueError(f"RetargetedClip {name!r}: fps must be positive and finite, got {self.fps!r}")
        set_(self, "fps", fps)

    @property
    def frames(self) -> int:
        """Number of frames F."""
        return int(self.bone_rotmats_local.shape[0])


def retarget_clip(
    clip: MocapClip,
    body: BodyModel,
    subject: SubjectFit | np.ndarray,
    config: RetargetConfig = RetargetConfig(),
) -> RetargetedClip:
    """Fit the body model to every frame of a mocap clip, with the subject's shape frozen.

    The clip is resampled to ``config.fps`` first (linear interpolation of positions, ``MocapClip.resample``).

    Args:
        clip: the mocap clip (for :data:`DAZ_CMU_LINKS`: a CMU Daz BVH read with ``include_end_sites=True``).
        body: the body model.
        subject: the subject's :class:`SubjectFit` (from :func:`fit_subject`), or only its (6,) phenotypes in
            [0, 1]: then the correspondence offsets are fitted on this clip first, with the shape frozen.
        config: the retarget settings.

    Returns:
        The :class:`RetargetedClip` (float64 arrays, at ``config.fps``).

    Raises:
        ValueError: a clip lacking mapped joints or with non-finite positions, phenotypes of the wrong shape or
            outside [0, 1], or a :class:`SubjectFit` made for another correspondence table.
        RuntimeError: the fit produced non-finite values (never expected; reported rather than returned).
    """
    with torch_threads(config.torch_threads):
        return _retarget_clip(clip, body, subject, config)


def _retarget_clip(
    clip: MocapClip, body: BodyModel, subject: SubjectFit | np.ndarray, config: RetargetConfig
) -> RetargetedClip:
    resolved = resolve_links(config.links, body.posed_bones, body.posed_parents)
    if isinstance(subject, SubjectFit):
        if tuple(subject.mapped_joint_names) != resolved.mocap_joints:
            raise ValueError(
                f"retarget_clip: the SubjectFit of subject {subject.subject!r} was made for the mapped joints "
                f"{list(subject.mapped_joint_names)}, the config's table maps {list(resolved.mocap_joints)}"
            )
        phenotypes, offsets = check_phenotypes(subject.phenotypes), np.asarray(subject.offsets_m)
    else:
        phenotypes = check_phenotypes(subject)
        mocap_targets_m(clip, resolved.mocap_joints)  # the clear error for a bad clip comes before any fitting
        offsets = fit_subject(clip, body, config, phenotypes=phenotypes).offsets_m
    resampled = clip if clip.fps == config.fps else clip.resample(config.fps)
    targets = torch.as_tensor(mocap_targets_m(resampled, resolved.mocap_joints), dtype=body.dtype)
    points = PointModel(body, resolved)
    with torch.no_grad():
        rest = body.rest_skeleton(torch.as_tensor(phenotypes, dtype=body.dtype)[None])
        coefficients = points.coefficients(rest, torch.as_tensor(offsets, dtype=body.dtype))
    rotmats, translation = fit_poses(points, coefficients, targets, config)
    with torch.no_grad():
        keypoints, joints = body.keypoints_and_joints(rest, rotmats[None], translation[None])
        residual_mm = (points.points(coefficients, rotmats, translation) - targets).norm(dim=-1) * 1000.0
    outputs = (rotmats, translation, keypoints, joints, residual_mm)
    if not all(bool(torch.isfinite(t).all()) for t in outputs):
        raise RuntimeError(f"retarget_clip: the fit of clip {clip.name!r} produced non-finite values")
    return RetargetedClip(
        name=clip.name,
        subject=clip.subject,
        fps=resampled.fps,
        phenotypes=phenotypes,
        bone_rotmats_local=rotmats.double().numpy(),
        root_translation_m=translation.double().numpy(),
        keypoints_world_m=keypoints[0].double().numpy(),
        joints_world_m=joints[0].double().numpy(),
        residual_mm=residual_mm.double().numpy(),
        mapped_joint_names=resolved.mocap_joints,
        offsets_m=offsets,
    )


def _load(source: MocapClip | str | Path, fps: float) -> MocapClip:
    if isinstance(source, MocapClip):
        clip = source
    elif isinstance(source, (str, Path)):
        path = Path(source)
        if not (path.name.endswith(".bvh") or path.name.endswith(".bvh.gz")):
            raise ValueError(f"retarget_clips reads BVH files (.bvh, .bvh.gz); got {path}")
        clip = read_bvh(path, include_end_sites=True)
    else:
        raise ValueError(f"retarget_clips takes MocapClip objects or BVH paths, got {type(source).__name__}")
    # Resample on load: a quarter of the memory of 120 fps clips while a subject's clips are held together.
    return clip if clip.fps == fps else clip.resample(fps)


def retarget_clips(
    sources: Iterable[MocapClip | str | Path],
    body: BodyModel,
    config: RetargetConfig = RetargetConfig(),
    progress: Callable[[int, int, str], None] | None = None,
) -> list[RetargetedClip]:
    """Retarget many clips: one shape per subject (fitted on all of that subject's clips), then every clip.

    Args:
        sources: clips, or paths of BVH files (read with ``include_end_sites=True``).
        body: the body model.
        config: the retarget settings.
        progress: called as ``progress(done, total, clip_name)`` after each clip.

    Returns:
        The retargeted clips, in the order of ``sources``.

    Raises:
        ValueError: no sources, a source that is neither a clip nor a BVH path, duplicated clip names, or a clip
            the correspondence cannot use (see :func:`retarget_clip`).
    """
    with torch_threads(config.torch_threads):
        return _retarget_clips(sources, body, config, progress)


def _retarget_clips(
    sources: Iterable[MocapClip | str | Path],
    body: BodyModel,
    config: RetargetConfig,
    progress: Callable[[int, int, str], None] | None,
) -> list[RetargetedClip]:
    start = time.perf_counter()
    clips = [_load(source, config.fps) for source in sources]
    if not clips:
        raise ValueError("retarget_clips: no clips given")
    names = [clip.name for clip in clips]
    duplicated = sorted({n for n in names if names.count(n) > 1})
    if duplicated:
        raise ValueError(f"retarget_clips: clip names must be unique, got duplicates {duplicated}")
    by_subject: dict[str, list[int]] = {}
    for index, clip in enumerate(clips):
        by_subject.setdefault(clip.subject, []).append(index)
    logger.info("retargeting %d clip(s) of %d subject(s) at %.0f fps", len(clips), len(by_subject), config.fps)
    results: list[RetargetedClip | None] = [None] * len(clips)
    done = 0
    for subject, indices in by_subject.items():
        fit = fit_subject([clips[i] for i in indices], body, config)
        for i in indices:
            clip_start = time.perf_counter()
            results[i] = retarget_clip(clips[i], body, fit, config)
            done += 1
            logger.info(
                "[%d/%d] %s: %d frames in %.1f s, median residual %.1f mm",
                done, len(clips), clips[i].name, results[i].frames, time.perf_counter() - clip_start,
                float(np.median(results[i].residual_mm)),
            )
            if progress is not None:
                progress(done, len(clips), clips[i].name)
        logger.debug("subject %s done", subject)
    logger.info("retargeted %d clip(s) in %.1f s", len(clips), time.perf_counter() - start)
    return [r for r in results if r is not None]
