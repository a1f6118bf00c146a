"""Biovision Hierarchy (BVH) files to joint world positions.

A BVH file has a HIERARCHY section (a joint tree: ``ROOT``/``JOINT`` with an ``OFFSET`` from the parent and the
``CHANNELS`` animated per frame, leaves closed by ``End Site``) and a MOTION section (``Frames:``,
``Frame Time:``, then one line of channel values per frame, in the order the channels were declared).

Kinematics (the reading every major BVH tool shares): a joint's local rotation is the product of its rotation
channels in the order declared, ``R = R_first @ R_second @ R_third`` (intrinsic Euler angles, degrees); its
position is ``p = p_parent + W_parent @ offset`` and its world rotation ``W = W_parent @ R``. Position channels
replace the OFFSET component of their axis (for a root whose OFFSET is zero this is the same as adding).

Read ``docs/mocap.md`` for the CMU Daz release specifics (a T-pose and a blend out of it at the start of every
file, centimetres, Y up).
"""

from __future__ import annotations

import io
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from humancal.mocap.bvh_hierarchy import BvhJoint, parse_hierarchy
from humancal.mocap.clip import MocapClip, MocapFormatError
from humancal.mocap.reading import (
    R_ZUP_FROM_YUP,
    clip_name_and_subject,
    euler_rotmat,
    floor_height_m,
    read_text_lines,
)

__all__ = ["BvhJoint", "BvhMotion", "parse_bvh", "bvh_forward_kinematics", "read_bvh", "CMU_DAZ_LEADING_FRAMES"]

logger = logging.getLogger(__name__)

CMU_DAZ_LEADING_FRAMES = 8
"""Frames to drop at the start of a CMU Daz BVH file: the added T-pose (frame 1) and the 7 frames in which the
retargeted limbs blend from it into the captured motion (``docs/mocap.md`` has the measurements)."""


@dataclass(frozen=True)
class BvhMotion:
    """A parsed BVH file, before kinematics and unit conversion.

    Attributes:
        path: the file.
        joints: nodes in file order (parents before children), End Sites included.
        values: (F, C) channel values per frame: positions in file units, rotations in degrees.
        frame_time_s: ``Frame Time`` of the file, seconds.
    """

    path: Path
    joints: tuple[BvhJoint, ...]
    values: np.ndarray
    frame_time_s: float

    @property
    def fps(self) -> float:
        """Frames per second, ``1 / frame_time_s`` snapped to an integer when within 0.01 % of one.

        ``Frame Time`` is usually printed with 6 significant digits (0.00833333 for 120 fps); snapping
        removes that rounding.
        """
        fps = 1.0 / self.frame_time_s
        nearest = round(fps)
        return float(nearest) if nearest > 0 and abs(fps - nearest) <= 1e-4 * nearest else fps


def _header_value(path: Path, lines: list[str], index: int, label: str) -> str:
    if index >= len(lines):
        raise MocapFormatError(path, len(lines), f"file ends before the '{label}' line of MOTION")
    line = lines[index].strip()
    if not line.lower().startswith(label.lower()):
        raise MocapFormatError(path, index + 1, f"expected '{label} <value>', found {line!r}")
    return line[len(label):].strip()


def _scan_values(path: Path, lines: list[str], first: int, n_frames: int, n_channels: int) -> None:
    """Find the first line of the frame block that breaks the declared layout, and raise naming it."""
    n_rows = 0
    for i in range(first, len(lines)):
        parts = lines[i].split()
        if not parts:
            continue
        if n_rows == n_frames:
            raise MocapFormatError(path, i + 1, f"more frame lines than the {n_frames} declared by 'Frames:'")
        n_rows += 1
        if len(parts) != n_channels:
            raise MocapFormatError(
                path, i + 1, f"frame {n_rows} has {len(parts)} values; expected {n_channels} (one per channel)"
            )
        for col, tok in enumerate(parts):
            try:
                value = float(tok)
            except ValueError:
                raise MocapFormatError(path, i + 1, f"expected a number in column {col + 1}, found {tok!r}") from None
            if not np.isfinite(value):
                raise MocapFormatError(
                    path, i + 1, f"non-finite value {tok!r} in column {col + 1}; expected finite numbers"
                )
    if n_rows < n_frames:
        raise MocapFormatError(
            path, len(lines), f"file is truncated: {n_rows} frame lines, expected {n_frames} ('Frames:')"
        )


def _parse_values(path: Path, lines: list[str], first: int, n_frames: int, n_channels: int) -> np.ndarray:
    if n_frames == 0:
        _scan_values(path, lines, first, n_frames, n_channels)  # raises on any frame line
        return np.zeros((0, n_channels))
    # numpy's C reader is the fast path; any surprise is located by the line-by-line scan, which raises.
    block = "\n".join(lines[first:])
    try:
        values = np.loadtxt(io.StringIO(block), dtype=np.float64, ndmin=2, comments=None)
    except ValueError:
        values = None
    if values is None or values.shape != (n_frames, n_channels) or not np.all(np.isfinite(values)):
        _scan_values(path, lines, first, n_frames, n_channels)
        raise MocapFormatError(path, None, "the MOTION values could not be read as a table of numbers")
    return values


def parse_bvh(path: str | Path) -> BvhMotion:
    """Parse a BVH file (plain or gzip) without interpreting it.

    Args:
        path: ``.bvh`` or ``.bvh.gz`` file.

    Returns:
        The hierarchy and the raw channel values.

    Raises:
        FileNotFoundError: no such file.
        MocapFormatError: naming the file, the line and what was expected (bad hierarchy, unknown channel,
            missing MOTION, a frame with the wrong number of values, a truncated file, non-finite values).
    """
    path = Path(path)
    lines = read_text_lines(path)
    motion = next((i for i, line in enumerate(lines) if line.strip() == "MOTION"), None)
    if motion is None:
        raise MocapFormatError(path, None, "no MOTION section (expected a line 'MOTION' after the HIERARCHY)")
    joints = parse_hierarchy(path, lines, motion)
    n_channels = sum(len(j.channels) for j in joints)
    frames_text = _header_value(path, lines, motion + 1, "Frames:")
    if not frames_text.isdigit():
        raise MocapFormatError(path, motion + 2, f"expected 'Frames: <count>', found {lines[motion + 1].strip()!r}")
    time_text = _header_value(path, lines, motion + 2, "Frame Time:")
    try:
        frame_time_s = float(time_text)
    except ValueError:
        frame_time_s = float("nan")
    if not (np.isfinite(frame_time_s) and frame_time_s > 0):
        raise MocapFormatError(path, motion + 3, f"expected 'Frame Time: <seconds > 0>', found {time_text!r}")
    values = _parse_values(path, lines, motion + 3, int(frames_text), n_channels)
    return BvhMotion(path, tuple(joints), values, frame_time_s)


def bvh_forward_kinematics(motion: BvhMotion) -> np.ndarray:
    """World positions of every node (End Sites included), in the file's units and axes.

    Args:
        motion: a parsed file.

    Returns:
        (F, N, 3) positions of the N nodes of ``motion.joints``, file units.
    """
    n_frames = motion.values.shape[0]
    has_children = {j.parent for j in motion.joints}
    positions = np.zeros((n_frames, len(motion.joints), 3))
    world_rot: dict[int, np.ndarray] = {}
    for j, joint in enumerate(motion.joints):
        offset = np.asarray(joint.offset, dtype=np.float64)
        pos_cols = {"xyz".index(ch[0].lower()): joint.first_column + k
                    for k, ch in enumerate(joint.channels) if ch.endswith("position")}
        if pos_cols:
            local = np.broadcast_to(offset, (n_frames, 3)).copy()
            for axis, col in pos_cols.items():
                local[:, axis] = motion.values[:, col]
        else:
            local = offset
        if joint.parent < 0:
            positions[:, j] = local
            parent_rot = None
        else:
            parent_rot = world_rot[joint.parent]
            moved = parent_rot @ local if local.ndim == 1 else np.einsum("fij,fj->fi", parent_rot, local)
            positions[:, j] = positions[:, joint.parent] + moved
        if j in has_children:  # leaves need no rotation of their own
            rot_cols = [(ch[0].lower(), joint.first_column + k)
                        for k, ch in enumerate(joint.channels) if ch.endswith("rotation")]
            rot = euler_rotmat("".join(a for a, _ in rot_cols), np.deg2rad(motion.values[:, [c for _, c in rot_cols]]))
            world_rot[j] = rot if parent_rot is None else parent_rot @ rot
    return positions


def read_bvh(
    path: str | Path,
    *,
    drop_leading_frames: int = CMU_DAZ_LEADING_FRAMES,
    metres_per_unit: float = 0.01,
    up_axis: str = "y",
    include_end_sites: bool = False,
    floor_percentile: float | None = 5.0,
) -> MocapClip:
    """Read a BVH file into joint world positions: metres, right-handed, Z up, floor at z = 0.

    The defaults fit the CMU "Daz-friendly" BVH release (``docs/mocap.md``): every file of it starts with an
    added T-pose (frame 1: root rotation exactly zero, about 80 % of the rotation channels within 0.5 deg of
    zero) and then blends the limbs from it into the capture (against the original AMC of the same captures,
    limb directions are off by a median 38, 24, 13 deg in frames 2-4 instead of the retarget's steady 7 deg,
    and again by up to 2 deg more in frames 6-8), so 8 frames are dropped; its lengths are centimetres (hip
    79 units above the ankles in the T-pose) and it is Y up. For other BVH files pass ``drop_leading_frames=0``
    unless they carry such frames too.

    Args:
        path: ``.bvh`` or ``.bvh.gz`` file.
        drop_leading_frames: frames to drop at the start of the file (CMU Daz: T-pose + blend, 8).
        metres_per_unit: metres per length unit of the file (0.01: centimetres).
        up_axis: the file's up axis: ``"y"`` (rotated to Z up by :data:`R_ZUP_FROM_YUP`) or ``"z"`` (kept).
        include_end_sites: also return the End Sites, as joints named ``<parent>_end``.
        floor_percentile: shift vertically so that this percentile over frames of the lowest node of each
            frame (End Sites included, whether returned or not) is at z = 0; ``None`` keeps the file's origin.

    Returns:
        The clip; ``fps`` from ``Frame Time``; name and subject from the file name ``SS_TT.bvh[.gz]``.

    Raises:
        FileNotFoundError: no such file.
        MocapFormatError: the file is malformed (see :func:`parse_bvh`), or has no frame left after the drop.
        ValueError: a bad argument.
    """
    if not (np.isfinite(metres_per_unit) and metres_per_unit > 0):
        raise ValueError(f"read_bvh: metres_per_unit must be positive, got {metres_per_unit!r}")
    if up_axis not in ("y", "z"):
        raise ValueError(f"read_bvh: up_axis must be 'y' or 'z', got {up_axis!r}")
    if floor_percentile is not None and not 0.0 <= floor_percentile <= 100.0:
        raise ValueError(f"read_bvh: floor_percentile must be in [0, 100] or None, got {floor_percentile!r}")
    if isinstance(drop_leading_frames, bool) or int(drop_leading_frames) != drop_leading_frames \
            or drop_leading_frames < 0:
        raise ValueError(f"read_bvh: drop_leading_frames must be a count >= 0, got {drop_leading_frames!r}")
    motion = parse_bvh(path)
    n_file = motion.values.shape[0]
    if n_file <= drop_leading_frames:
        raise MocapFormatError(
            motion.path, None, f"{n_file} frame(s): nothing left after dropping {drop_leading_frames} leading frame(s)"
        )
    kept = BvhMotion(motion.path, motion.joints, motion.values[int(drop_leading_frames):], motion.frame_time_s)
    positions = bvh_forward_kinematics(kept) * metres_per_unit
    if up_axis == "y":
        positions = positions @ R_ZUP_FROM_YUP.T
    if floor_percentile is not None:
        positions[..., 2] -= floor_height_m(positions[..., 2], floor_percentile)
    keep = [j for j, joint in enumerate(motion.joints) if include_end_sites or not joint.is_end_site]
    new_index = {old: new for new, old in enumerate(keep)}
    parents = tuple(new_index[motion.joints[j].parent] if motion.joints[j].parent >= 0 else -1 for j in keep)
    name, subject = clip_name_and_subject(motion.path)
    logger.debug("read %s: %d frames, %d joints at %.3f fps", motion.path, positions.shape[0], len(keep), motion.fps)
    return MocapClip(
        name=name,
        subject=subject,
        joint_names=tuple(motion.joints[j].name for j in keep),
        parents=parents,
        positions_world_m=positions[:, keep],
        fps=motion.fps,
        source_path=motion.path,
    )
