"""Training windows for the motion prior: clips of posed-bone rotations, windows, and the paper's augmentation.

A :class:`MotionClips` holds the 21 non-root bone rotations of every clip back to back (the root, bone 0, is
the body's global orientation and is not modelled), with each clip's subject and phenotypes.
:func:`sample_windows` draws windows of ``clip_frames`` frames with the augmentation of section IV of the paper:

- **time resampling** (up- and down-sampling): the window plays the clip at a speed factor ``s`` drawn
  log-uniformly from ``speed_range``; frame ``k`` of the window is source time ``t0 + s k``, between two source
  frames, interpolated by spherical linear interpolation of each bone's rotation (exact slerp:
  ``R0 exp(w log(R0^T R1))``);
- **reversal**: the frames in reverse order;
- **left-right mirroring** along the kinematic tree (:func:`mirror_bone_rotmats`).

Mirroring: the body's lateral axis is x (the reference pose faces -y with its left side at +x, Z up;
``docs/body_model.md``), so the reflection across the sagittal plane is ``M = diag(-1, 1, 1)``. anny's
"local-ref" rotations act in world-aligned axes, so the mirror of a rotation is ``M R M`` and the forward
kinematics of the mirrored rotations is the mirrored body, once each left bone takes its right twin's
rotation. Both steps are exact (sign flips and a swap), so mirroring twice returns the input bit for bit.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import roma
import torch

from humancal.body.bones import POSED_BONE_NAMES
from humancal.prior.config import NUM_PRIOR_BONES, PriorConfig

__all__ = [
    "MIRROR_BONE_PERMUTATION",
    "MotionClips",
    "MotionWindows",
    "clips_from_retargeted",
    "mirror_bone_rotmats",
    "sample_windows",
    "slerp_rotmats",
]

_MIRROR_SIGNS = np.array([-1.0, 1.0, 1.0])


def _mirror_name(name: str) -> str:
    if name.endswith(".L"):
        return name[:-2] + ".R"
    if name.endswith(".R"):
        return name[:-2] + ".L"
    return name


MIRROR_BONE_PERMUTATION: tuple[int, ...] = tuple(
    POSED_BONE_NAMES.index(_mirror_name(name)) for name in POSED_BONE_NAMES
)
"""For each of the 22 posed bones, the index of its left-right twin (itself for the bones on the midline)."""


def mirror_bone_rotmats(bone_rotmats: torch.Tensor | np.ndarray) -> torch.Tensor | np.ndarray:
    """Mirror poses left-right across the sagittal plane (x -> -x) along the kinematic tree.

    Args:
        bone_rotmats: (..., 22, 3, 3) rotations of all posed bones (root first), or (..., 21, 3, 3) those of
            posed bones 1..21 (the prior's input), anny "local-ref".

    Returns:
        The same shape and type: each bone takes its twin's rotation ``R``, reflected as ``M R M`` with
        ``M = diag(-1, 1, 1)``. An involution, exact in floating point. A root translation mirrors as
        ``x -> -x`` (not handled here).

    Raises:
        ValueError: not (..., 22, 3, 3) or (..., 21, 3, 3).
    """
    shape = tuple(bone_rotmats.shape)
    if len(shape) < 3 or shape[-2:] != (3, 3) or shape[-3] not in (NUM_PRIOR_BONES, NUM_PRIOR_BONES + 1):
        raise ValueError(
            f"bone_rotmats must have shape (..., {NUM_PRIOR_BONES + 1}, 3, 3) or (..., {NUM_PRIOR_BONES}, 3, 3), "
            f"got {shape}"
        )
    permutation = np.asarray(MIRROR_BONE_PERMUTATION)
    if shape[-3] == NUM_PRIOR_BONES:
        permutation = permutation[1:] - 1
    # (M R M)_ij = s_i s_j R_ij with s = diag(M): a sign pattern, so the reflection is exact.
    signs = _MIRROR_SIGNS[:, None] * _MIRROR_SIGNS[None, :]
    if isinstance(bone_rotmats, torch.Tensor):
        signs_t = torch.as_tensor(signs, dtype=bone_rotmats.dtype, device=bone_rotmats.device)
        index = torch.as_tensor(permutation, device=bone_rotmats.device)
        return bone_rotmats.index_select(-3, index) * signs_t
    return np.asarray(bone_rotmats)[..., permutation, :, :] * signs.astype(np.asarray(bone_rotmats).dtype)


def slerp_rotmats(R0: torch.Tensor, R1: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    """Spherical linear interpolation of rotation matrices, ``R0 exp(w log(R0^T R1))`` (shortest arc).

    Args:
        R0, R1: (..., 3, 3) rotations.
        weight: (...) interpolation weights (0 gives ``R0``, 1 gives ``R1``), broadcast against the batch.

    Returns:
        (..., 3, 3) rotations.
    """
    delta = roma.rotmat_to_rotvec(R0.transpose(-1, -2) @ R1)
    return R0 @ roma.rotvec_to_rotmat(weight[..., None] * delta)


@dataclass(frozen=True)
class MotionClips:
    """Motion clips for the prior, stored back to back.

    Attributes:
        bone_rotmats: (N, 21, 3, 3) float32 rotations of posed bones 1..21 of every frame of every clip.
        starts: (C + 1,) int64 frame offsets: clip ``c`` is ``bone_rotmats[starts[c]:starts[c + 1]]``.
        names: C clip names.
        subjects: C subject names (held-out splits are by whole subjects).
        phenotypes: (C, 6) float32 phenotypes of the clips' bodies (``humancal.body.PHENOTYPE_NAMES``).
        fps: C frame rates, frames per second.
    """

    bone_rotmats: torch.Tensor
    starts: np.ndarray
    names: tuple[str, ...]
    subjects: tuple[str, ...]
    phenotypes: np.ndarray
    fps: tuple[float, ...]

    @property
    def num_clips(self) -> int:
        """C, the number of clips."""
        return len(self.names)

    @property
    def lengths(self) -> np.ndarray:
        """(C,) frames of each clip."""
        return np.diff(self.starts)

    def select(self, clip_indices: Sequence[int]) -> MotionClips:
        """A subset of the clips, in the given order."""
        parts = [self.bone_rotmats[self.starts[c] : self.starts[c + 1]] for c in clip_indices]
        lengths = [len(p) for p in parts]
        return MotionClips(
            bone_rotmats=torch.cat(parts) if parts else self.bone_rotmats[:0],
            starts=np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64),
            names=tuple(self.names[c] for c in clip_indices),
            subjects=tuple(self.subjects[c] for c in clip_indices),
            phenotypes=self.phenotypes[list(clip_indices)],
            fps=tuple(self.fps[c] for c in clip_indices),
        )

    def split_subjects(self, held_out: Sequence[str]) -> tuple[MotionClips, MotionClips]:
        """(training clips, held-out clips) by whole subjects.

        Raises:
            ValueError: one of the two parts is empty (names the subjects found).
        """
        held = set(held_out)
        train = [c for c in range(self.num_clips) if self.subjects[c] not in held]
        val = [c for c in range(self.num_clips) if self.subjects[c] in held]
        if not train or not val:
            raise ValueError(
                f"holding out subjects {sorted(held)} leaves {len(train)} training and {len(val)} held-out clips; "
                f"the clips' subjects are {sorted(set(self.subjects))}"
            )
        return self.select(train), self.select(val)

    def digest(self) -> str:
        """Hex SHA-256 of the clips' rotations, boundaries, names, subjects and phenotypes (names the data)."""
        digest = hashlib.sha256()
        digest.update(self.bone_rotmats.detach().cpu().contiguous().numpy().tobytes())
        digest.update(self.starts.astype(np.int64).tobytes())
        digest.update("\n".join(self.names).encode())
        digest.update("\n".join(self.subjects).encode())
        digest.update(np.ascontiguousarray(self.phenotypes, dtype=np.float32).tobytes())
        return digest.hexdigest()


def clips_from_retargeted(clips: Sequence) -> MotionClips:
    """The prior's view of retargeted clips (``humancal.retarget.RetargetedClip`` or anything with the same
    ``name``, ``subject``, ``fps``, ``phenotypes`` (6,) and ``bone_rotmats_local`` (T, 22, 3, 3) attributes).

    Raises:
        ValueError: no clips, a clip with a wrong rotation shape or non-finite values.
    """
    if len(clips) == 0:
        raise ValueError("clips is empty: the motion prior needs at least one retargeted clip")
    rotations, names, subjects, phenotypes, fps = [], [], [], [], []
    for clip in clips:
        R = np.asarray(clip.bone_rotmats_local, dtype=np.float32)
        if R.ndim != 4 or R.shape[1:] != (NUM_PRIOR_BONES + 1, 3, 3) or len(R) < 1:
            raise ValueError(
                f"clip {clip.name!r}: bone_rotmats_local must have shape (T, {NUM_PRIOR_BONES + 1}, 3, 3), "
                f"got {R.shape}"
            )
        if not np.isfinite(R).all():
            raise ValueError(f"clip {clip.name!r}: bone_rotmats_local has non-finite values")
        rotations.append(R[:, 1:])
        names.append(str(clip.name))
        subjects.append(str(clip.subject))
        phenotypes.append(np.asarray(clip.phenotypes, dtype=np.float32).reshape(6))
        fps.append(float(clip.fps))
    lengths = [len(r) for r in rotations]
    return MotionClips(
        bone_rotmats=torch.from_numpy(np.concatenate(rotations)),
        starts=np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64),
        names=tuple(names),
        subjects=tuple(subjects),
        phenotypes=np.stack(phenotypes),
        fps=tuple(fps),
    )


@dataclass(frozen=True)
class MotionWindows:
    """A batch of windows.

    Attributes:
        bone_rotmats: (B, T, 21, 3, 3) float32 rotations of posed bones 1..21.
        clip_index: (B,) int64 the clip each window came from (index into the :class:`MotionClips`).
    """

    bone_rotmats: torch.Tensor
    clip_index: np.ndarray


def sample_windows(
    clips: MotionClips, num_windows: int, config: PriorConfig, rng: np.random.Generator, augment: bool = True
) -> MotionWindows:
    """Draw windows of ``config.clip_frames`` frames, augmented as the module docstring says.

    A clip is chosen with probability proportional to its number of possible window starts (at speed 1), so
    every frame of the data is about equally likely; a resampled window whose span does not fit in its clip
    plays at the fastest speed that fits (clips shorter than a window are never chosen).

    Args:
        clips: the clips to draw from.
        num_windows: B.
        config: ``clip_frames`` and the augmentation fields (``resample_prob``, ``speed_range``,
            ``reverse_prob``, ``mirror_prob``).
        rng: the only source of randomness.
        augment: False draws plain windows (speed 1, forward, not mirrored), e.g. for validation.

    Returns:
        The :class:`MotionWindows`.

    Raises:
        ValueError: no clip has ``clip_frames`` frames.
    """
    frames = config.clip_frames
    starts_possible = np.maximum(clips.lengths - frames + 1, 0)
    if starts_possible.sum() == 0:
        raise ValueError(f"no clip has the {frames} frames of a window (longest: {int(clips.lengths.max())})")
    clip_index = rng.choice(clips.num_clips, size=num_windows, p=starts_possible / starts_possible.sum())
    lengths = clips.lengths[clip_index].astype(np.float64)
    speed = np.ones(num_windows)
    if augment:
        resample = rng.random(num_windows) < config.resample_prob
        low, high = np.log(config.speed_range[0]), np.log(config.speed_range[1])
        drawn = np.exp(rng.uniform(low, high, num_windows))
        speed = np.where(resample, drawn, 1.0)
        speed = np.minimum(speed, (lengths - 1.0) / (frames - 1))
    span = speed * (frames - 1)
    t0 = rng.random(num_windows) * (lengths - 1.0 - span)
    t0 = np.where(speed == 1.0, np.floor(t0), t0)  # plain windows start on a frame: no interpolation
    times = t0[:, None] + speed[:, None] * np.arange(frames)[None, :]
    times = np.clip(times, 0.0, lengths[:, None] - 1.0)
    before = np.floor(times).astype(np.int64)
    after = np.minimum(before + 1, lengths[:, None].astype(np.int64) - 1)
    weight = times - before
    offset = clips.starts[clip_index][:, None]
    R0 = clips.bone_rotmats[torch.from_numpy(offset + before)]
    R1 = clips.bone_rotmats[torch.from_numpy(offset + after)]
    w = torch.from_numpy(weight).to(R0.dtype)[:, :, None].expand(-1, -1, NUM_PRIOR_BONES)
    needs = w > 0
    bone_rotmats = R0.clone()
    if bool(needs.any()):
        # Slerp in float64: the float32 log map of near-identity deltas is noisy.
        bone_rotmats[needs] = slerp_rotmats(R0[needs].double(), R1[needs].double(), w[needs].double()).to(R0.dtype)
    if augment:
        reverse = torch.from_numpy(rng.random(num_windows) < config.reverse_prob)
        bone_rotmats[reverse] = bone_rotmats[reverse].flip(1)
        mirror = torch.from_numpy(rng.random(num_windows) < config.mirror_prob)
        bone_rotmats[mirror] = mirror_bone_rotmats(bone_rotmats[mirror])
    return MotionWindows(bone_rotmats=bone_rotmats, clip_index=clip_index)
