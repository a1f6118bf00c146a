"""Acclaim AMC motion files, read against their ASF skeleton (:mod:`humancal.mocap.asf`), to joint positions.

AMC gives, per frame, the root translation and rotation (channels in the ``order`` of the ASF ``:root``) and
each animated bone's dof values (``:FULLY-SPECIFIED``: every animated bone in every frame).

Kinematics (the ASF specification, column vectors): rotations "in the order given" apply the first one
first, so ``axis 0 0 20 XYZ`` is ``C = Rz(20) @ Ry(0) @ Rx(0)`` and ``dof rx rz`` with values (a, b) is
``M = Rz(b) @ Rx(a)``. A bone's rotation in its parent's frame is ``L = C M C^-1`` (the spec's ``C^-1 M C``
written for row vectors); its world rotation is ``W = W_parent @ L`` and its end lies at
``end_parent + length * W @ direction``. The root's rotation is ``C_root M_root C_root^-1`` with C_root from
``:root`` ``orientation``/``axis``; its position is the AMC translation (the ASF ``position`` is not added;
it is zero in every CMU file).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from humancal.mocap.asf import AsfBone, AsfSkeleton, read_asf
from humancal.mocap.clip import MocapClip, MocapFormatError
from humancal.mocap.reading import (
    R_ZUP_FROM_YUP,
    clip_name_and_subject,
    euler_rotmat,
    floor_height_m,
    read_text_lines,
)

__all__ = ["AsfBone", "AsfSkeleton", "read_asf", "read_amc", "asf_rest_positions", "CMU_FPS"]

logger = logging.getLogger(__name__)

CMU_FPS = 120.0
"""Frame rate of every CMU capture (AMC files do not store it)."""


def _amc_columns(skeleton: AsfSkeleton) -> tuple[dict[str, slice], int]:
    """Column slice of the root and of every animated bone in a frame's value row, and the row width."""
    columns: dict[str, slice] = {"root": slice(0, len(skeleton.root_order))}
    start = len(skeleton.root_order)
    for bone in skeleton.bones:
        if bone.dof:
            columns[bone.name] = slice(start, start + len(bone.dof))
            start += len(bone.dof)
    return columns, start


def _amc_header(path: Path, lines: list[str], degrees: bool) -> tuple[int, bool]:
    """Index of the first frame-number line, and whether angles are degrees (``:DEGREES``/``:RADIANS``)."""
    for i, raw in enumerate(lines):
        parts = raw.split()
        if not parts or parts[0].startswith("#"):
            continue
        if parts[0].startswith(":"):
            keyword = parts[0].upper()
            if keyword == ":DEGREES":
                degrees = True
            elif keyword == ":RADIANS":
                degrees = False
            elif keyword != ":FULLY-SPECIFIED":
                raise MocapFormatError(path, i + 1, f"unknown AMC keyword {parts[0]!r}")
            continue
        if len(parts) == 1 and parts[0].isdigit():
            return i, degrees
        raise MocapFormatError(path, i + 1, f"expected a frame number before bone values, found {parts[0]!r}")
    raise MocapFormatError(path, len(lines), "no frames (expected a frame number line, then bone values)")


def _amc_values_fast(lines: list[str], first: int, columns: dict[str, slice], n_cols: int) -> np.ndarray | None:
    """Values of a regular file (every frame lists the same bones in the same order), or ``None``.

    Reads each bone's lines with numpy's C reader; any irregularity returns ``None`` and the careful
    line-by-line reader takes over (and names the line at fault).
    """
    end = len(lines)
    while end > first and not lines[end - 1].strip():
        end -= 1
    body = lines[first:end]
    per = 1
    while per < len(body) and not body[per].strip().isdigit():
        per += 1
    names = [body[j].split(None, 1)[0] if body[j].strip() else "" for j in range(1, per)]
    if len(names) != len(columns) or set(names) != set(columns) or len(body) % per:
        return None
    n_frames = len(body) // per
    if [line.strip() for line in body[0::per]] != [str(k) for k in range(1, n_frames + 1)]:
        return None
    values = np.empty((n_frames, n_cols))
    for j, name in enumerate(names, start=1):
        prefix, cols = name + " ", columns[name]
        n = len(prefix)
        numbers = [line[n:] for line in body[j::per] if line.startswith(prefix)]
        if len(numbers) != n_frames:
            return None
        try:
            block = np.loadtxt(numbers, dtype=np.float64, ndmin=2, comments=None)
        except ValueError:
            return None
        if block.shape != (n_frames, cols.stop - cols.start):
            return None
        values[:, cols] = block
    return values if np.all(np.isfinite(values)) else None


def _amc_values_careful(path: Path, lines: list[str], first: int, columns: dict[str, slice], n_cols: int,
                        bone_file: str) -> np.ndarray:
    """Values read line by line; raises naming the first line that breaks the format."""
    frames: list[list[str]] = []
    frame_lines: list[int] = []
    current: list[str] = []
    seen: set[str] = set()

    def close_frame(line_no: int) -> None:
        missing = [n for n in columns if n not in seen]
        if missing:
            raise MocapFormatError(
                path, line_no, f"frame {len(frames)} lacks {', '.join(missing)} (expected every animated bone once)"
            )

    for i in range(first, len(lines)):
        no, parts = i + 1, lines[i].split()
        if not parts:
            continue
        if len(parts) == 1 and parts[0].isdigit():
            if frames:
                close_frame(no)
            if int(parts[0]) != len(frames) + 1:
                raise MocapFormatError(path, no, f"expected frame number {len(frames) + 1}, found {parts[0]}")
            current = [""] * n_cols
            frames.append(current)
            frame_lines.append(no)
            seen = set()
            continue
        cols = columns.get(parts[0])
        if cols is None:
            raise MocapFormatError(path, no, f"bone {parts[0]!r} is not an animated bone of {bone_file}")
        if parts[0] in seen:
            raise MocapFormatError(path, no, f"bone {parts[0]!r} appears twice in frame {len(frames)}")
        width = cols.stop - cols.start
        if len(parts) - 1 != width:
            raise MocapFormatError(path, no, f"{parts[0]} has {len(parts) - 1} values; expected {width} (its dof)")
        current[cols] = parts[1:]
        seen.add(parts[0])
    close_frame(len(lines))
    for frame, no in zip(frames, frame_lines):
        for col, tok in enumerate(frame):
            try:
                value = float(tok)
            except ValueError:
                value = None
            if value is None or not np.isfinite(value):
                name = next(n for n, s in columns.items() if s.start <= col < s.stop)
                what = "non-finite value" if value is not None else f"non-number {tok!r}"
                raise MocapFormatError(
                    path, no, f"{what} for {name} in the frame starting here; expected finite numbers"
                )
    return np.array(frames, dtype=np.float64)


def _parse_amc(path: Path, skeleton: AsfSkeleton) -> tuple[np.ndarray, dict[str, slice], bool]:
    """AMC values as (F, C) plus each bone's column slice, and whether angles are degrees."""
    lines = read_text_lines(path)
    columns, n_cols = _amc_columns(skeleton)
    first, degrees = _amc_header(path, lines, skeleton.angle_unit == "deg")
    values = _amc_values_fast(lines, first, columns, n_cols)
    if values is None:
        values = _amc_values_careful(path, lines, first, columns, n_cols, skeleton.path.name)
    return values, columns, degrees


def _rotmat_in_order(axes: str, angles_rad: np.ndarray) -> np.ndarray:
    """Rotations applied in the order given (first axis first): the intrinsic product in reverse order."""
    return euler_rotmat(axes[::-1], angles_rad[..., ::-1])


def _forward_kinematics(
    skeleton: AsfSkeleton, values: np.ndarray, columns: dict[str, slice], to_rad: float
) -> np.ndarray:
    """(F, 1 + bones, 3) positions in file units and axes."""
    n = values.shape[0]
    root = values[:, columns["root"]]
    order = skeleton.root_order
    translation = np.zeros((n, 3))
    for k, axis in enumerate("xyz"):
        if f"t{axis}" in order:
            translation[:, k] = root[:, order.index(f"t{axis}")]
    rot_channels = [ch for ch in order if ch.startswith("r")]
    rot_values = root[:, [order.index(c) for c in rot_channels]]
    m_root = _rotmat_in_order("".join(ch[1] for ch in rot_channels), to_rad * rot_values)
    # ASF angles (root orientation, bone axes) follow the ASF :units; AMC values may say otherwise.
    asf_to_rad = np.pi / 180.0 if skeleton.angle_unit == "deg" else 1.0
    c_root = _rotmat_in_order(skeleton.root_axis_order, asf_to_rad * np.asarray(skeleton.root_orientation))
    world = [c_root @ m_root @ c_root.T]
    positions = np.zeros((n, len(skeleton.bones) + 1, 3))
    positions[:, 0] = translation
    for b, bone in enumerate(skeleton.bones):
        parent_world = world[bone.parent + 1]
        if bone.dof:
            c = _rotmat_in_order(bone.axis_order, asf_to_rad * np.asarray(bone.axis_angles))
            m = _rotmat_in_order("".join(d[1] for d in bone.dof), to_rad * values[:, columns[bone.name]])
            w = parent_world @ (c @ m @ c.T)
        else:
            w = parent_world
        world.append(w)
        rest = bone.length * np.asarray(bone.direction)
        positions[:, b + 1] = positions[:, bone.parent + 1] + np.einsum("fij,j->fi", w, rest)
    return positions


def asf_rest_positions(skeleton: AsfSkeleton) -> np.ndarray:
    """Joint positions of the skeleton at rest (every dof zero, root at the origin), metres, Z up.

    Returns:
        (1 + bones, 3) positions of :attr:`AsfSkeleton.joint_names`, metres, right-handed, Z up,
        not shifted to the floor.
    """
    columns, n_cols = _amc_columns(skeleton)
    values = np.zeros((1, n_cols))
    positions = _forward_kinematics(skeleton, values, columns, 1.0)[0]
    return (positions * skeleton.metres_per_unit) @ R_ZUP_FROM_YUP.T


def read_amc(
    path: str | Path,
    skeleton: AsfSkeleton,
    *,
    fps: float = CMU_FPS,
    metres_per_unit: float | None = None,
    floor_percentile: float | None = 5.0,
) -> MocapClip:
    """Read an AMC motion file (plain or gzip) into joint world positions: metres, right-handed, Z up, floor z = 0.

    Args:
        path: ``.amc`` or ``.amc.gz`` file.
        skeleton: its subject's skeleton, from :func:`read_asf`.
        fps: frame rate; AMC files do not store it, and every CMU capture is 120 fps.
        metres_per_unit: metres per file length unit; ``None`` uses ``skeleton.metres_per_unit``
            (0.0254 / 0.45 for CMU).
        floor_percentile: shift vertically so that this percentile over frames of the lowest joint of each
            frame is at z = 0; ``None`` keeps the file's origin.

    Returns:
        The clip: joints ``root`` and the end of every bone (named after the bone; ``ltibia`` is the left
        ankle, ``lfemur`` the left knee, ``head`` the top of the head bone), file Y up turned Z up by
        :data:`humancal.mocap.reading.R_ZUP_FROM_YUP`.

    Raises:
        FileNotFoundError: no such file.
        MocapFormatError: naming the file, the line and what was expected (unknown bone, wrong number of
            values, missing bone in a frame, frame numbers out of sequence, non-numbers, non-finite values).
        ValueError: a bad argument.
    """
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"read_amc: fps must be positive, got {fps!r}")
    if floor_percentile is not None and not 0.0 <= floor_percentile <= 100.0:
        raise ValueError(f"read_amc: floor_percentile must be in [0, 100] or None, got {floor_percentile!r}")
    scale = skeleton.metres_per_unit if metres_per_unit is None else float(metres_per_unit)
    if not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"read_amc: metres_per_unit must be positive, got {metres_per_unit!r}")
    path = Path(path)
    values, columns, degrees = _parse_amc(path, skeleton)
    positions = _forward_kinematics(skeleton, values, columns, np.pi / 180.0 if degrees else 1.0)
    positions = (positions * scale) @ R_ZUP_FROM_YUP.T
    if floor_percentile is not None:
        positions[..., 2] -= floor_height_m(positions[..., 2], floor_percentile)
    name, subject = clip_name_and_subject(path)
    logger.debug("read %s: %d frames, %d joints", path, positions.shape[0], positions.shape[1])
    return MocapClip(
        name=name,
        subject=subject,
        joint_names=skeleton.joint_names,
        parents=skeleton.parents,
        positions_world_m=positions,
        fps=fps,
        source_path=path,
    )
