"""Fitted motions to BVH: one file per person, anny's 22 posed bones, Y up, metres.

The skeleton is the posed-bone tree of :mod:`humancal.body.bones` with the person's reference-pose offsets
(``RestSkeleton.chain_offsets_m``). Every joint has a zero rest orientation, so a joint's BVH rotation is the
bone's "local-ref" rotation ``D_b`` itself (world-aligned axes of the reference pose, composed child after
parent): BVH's ``W_b = W_parent @ R_b``, ``p_b = p_parent + W_parent @ OFFSET_b`` is exactly humancal's forward
kinematics, and the joint positions of the file are ``BodyModel.joints`` (posed-bone heads).

Axes: BVH has no standard up axis; the file is **Y up, metres**, the reference pose facing +Z with its left at
+X (``R_YUP_FROM_ZUP``), which is what Blender's importer expects with its default options (forward -Z, up Y,
scale 1): imported there the motion lands in humancal's world (Z up, metres).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import torch

from humancal.body import BodyModel
from humancal.body.bones import POSED_BONE_NAMES
from humancal.fitting import FittedMotions
from humancal.formats.errors import FormatError
from humancal.formats.motions._common import (
    R_YUP_FROM_ZUP,
    PersonSpan,
    atomic_write_bytes,
    check_motions,
    person_spans,
)
from humancal.formats.motions.euler import continuous_euler_deg

__all__ = ["EULER_ORDERS", "bvh_text", "write_bvh"]

EULER_ORDERS: dict[str, str] = {name: "yzx" for name in POSED_BONE_NAMES} | {
    "upperarm01.L": "zyx",
    "upperarm01.R": "zyx",
}
"""Rotation channel order of each joint (intrinsic, BVH's ``R = R_first @ R_second @ R_third``), in the file's
Y-up axes. The middle angle of an Euler triple is singular at +-90 deg, so it is the axis a joint rarely turns
far about: Z (forward: abduction, lateral bend) for the legs, spine, elbows (hinge mostly about X and Y) and
the root; Y (up) for the shoulders, which abduct beyond 90 deg about Z."""

END_SITES: dict[str, tuple[str, float]] = {
    "head": ("up", 2.0),
    "wrist.L": ("along", 0.7),
    "wrist.R": ("along", 0.7),
    "toes.L": ("along", 0.35),
    "toes.R": ("along", 0.35),
}
"""End Site of each leaf (display only, importers draw the leaf bone towards it): ``("along", k)`` continues
the leaf's own offset from its parent scaled by k; ``("up", k)`` points up by k times that offset's length."""


def _end_site_offset(name: str, offset_m: np.ndarray) -> np.ndarray:
    kind, scale = END_SITES.get(name, ("along", 0.5))
    if kind == "up":
        return np.array([0.0, 0.0, scale * float(np.linalg.norm(offset_m))])
    return scale * offset_m


def _hierarchy_lines(names: tuple[str, ...], parents: tuple[int, ...], offsets_m: np.ndarray) -> list[str]:
    children: dict[int, list[int]] = {i: [] for i in range(len(names))}
    for i, p in enumerate(parents):
        if p >= 0:
            children[p].append(i)
    lines = ["HIERARCHY"]

    def vec(v: np.ndarray) -> str:
        return " ".join(f"{x:.6f}" for x in (R_YUP_FROM_ZUP @ v))

    def emit(i: int, depth: int) -> None:
        pad = "\t" * depth
        order = EULER_ORDERS[names[i]]
        rotation = " ".join(f"{axis.upper()}rotation" for axis in order)
        if parents[i] < 0:
            lines.append(f"{pad}ROOT {names[i]}")
            channels = f"6 Xposition Yposition Zposition {rotation}"
            offset = np.zeros(3)
        else:
            lines.append(f"{pad}JOINT {names[i]}")
            channels = f"3 {rotation}"
            offset = offsets_m[i]
        lines.extend([f"{pad}{{", f"{pad}\tOFFSET {vec(offset)}", f"{pad}\tCHANNELS {channels}"])
        for child in children[i]:
            emit(child, depth + 1)
        if not children[i]:
            end = _end_site_offset(names[i], offsets_m[i])
            lines.extend([f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET {vec(end)}", f"{pad}\t}}"])
        lines.append(f"{pad}}}")

    for root in (i for i, p in enumerate(parents) if p < 0):
        emit(root, 0)
    return lines


def bvh_text(
    offsets_m: np.ndarray,
    parents: tuple[int, ...],
    bone_rotmats_local: np.ndarray,
    root_translation_m: np.ndarray,
    fps: float,
    names: tuple[str, ...] = POSED_BONE_NAMES,
) -> str:
    """The BVH file of one person's motion.

    Args:
        offsets_m: (B, 3) head of each bone minus its parent's head in the reference pose, humancal's world
            axes (Z up), metres (root row ignored).
        parents: (B,) parent index of each bone, -1 for the root; parents before children.
        bone_rotmats_local: (T, B, 3, 3) "local-ref" rotations, humancal's world axes.
        root_translation_m: (T, 3) world position of the root head, metres.
        fps: frames per second (``Frame Time`` is its inverse).
        names: (B,) joint names.

    Returns:
        The text: Y up, metres, root with 6 channels (position then rotation), the others 3 rotation channels
        in the order :data:`EULER_ORDERS`, angles in degrees and continuous over time.
    """
    num_frames, num_bones = bone_rotmats_local.shape[:2]
    lines = _hierarchy_lines(names, parents, offsets_m)
    # Change of basis to Y up: R' = C R C^T for every rotation, p' = C p for every position.
    C = R_YUP_FROM_ZUP
    rotmats = C @ bone_rotmats_local @ C.T
    columns = [root_translation_m @ C.T]
    angles = np.empty((num_frames, num_bones, 3))
    for order in sorted(set(EULER_ORDERS[n] for n in names)):
        bones = [b for b, n in enumerate(names) if EULER_ORDERS[n] == order]
        angles[:, bones] = continuous_euler_deg(rotmats[:, bones], order)
    # Channels in file order: the hierarchy is written depth first, the MOTION columns follow it.
    for name in _depth_first(names, parents):
        columns.append(angles[:, names.index(name)])
    values = np.concatenate(columns, axis=1)
    buffer = io.StringIO()
    np.savetxt(buffer, values, fmt="%.6f", delimiter=" ")
    lines += ["MOTION", f"Frames: {num_frames}", f"Frame Time: {1.0 / fps:.8f}"]
    return "\n".join(lines) + "\n" + buffer.getvalue()


def _depth_first(names: tuple[str, ...], parents: tuple[int, ...]) -> list[str]:
    order: list[str] = []

    def visit(i: int) -> None:
        order.append(names[i])
        for child in (j for j, p in enumerate(parents) if p == i):
            visit(child)

    for root in (i for i, p in enumerate(parents) if p < 0):
        visit(root)
    return order


def _check_even_frames(motions: FittedMotions, span: PersonSpan) -> None:
    steps = np.diff(motions.frames[span.slice])
    if steps.size and not np.all(steps == steps[0]):
        raise FormatError(None, "FittedMotions.frames", "evenly spaced frame numbers (BVH has one Frame Time)",
                          f"steps {sorted(set(steps.tolist()))} for person {span.person_id}")


def bvh_file_name(person_id: int) -> str:
    """The file name of a person's BVH: ``person_<id>.bvh``."""
    return f"person_{person_id}.bvh"


def write_bvh(motions: FittedMotions, body: BodyModel, out_dir: str | Path) -> list[Path]:
    """Write one BVH file per person, ``<out_dir>/person_<id>.bvh``, over their first..last present frame.

    BVH frame 0 is the person's first present frame; ``Frame Time`` is ``1 / motions.fps``.

    Args:
        motions: the fitted motions.
        body: the body model (the reference-pose offsets of each person's shape).
        out_dir: output folder (created when missing).

    Returns:
        The files written, in person order.

    Raises:
        FormatError: bad motions (see :func:`~humancal.formats.motions._common.check_motions`), or frame numbers
            not evenly spaced within a person's span. Nothing is written then: every text is built first, and
            each file is written atomically.
    """
    motions = check_motions(motions)
    spans = person_spans(motions)
    for span in spans:
        _check_even_frames(motions, span)
    phenotypes = torch.as_tensor(motions.phenotypes, dtype=body.dtype, device=body.device)
    offsets = body.rest_skeleton(phenotypes).chain_offsets_m.detach().cpu().double().numpy()
    texts = {}
    for span in spans:
        texts[Path(out_dir) / bvh_file_name(span.person_id)] = bvh_text(
            offsets[span.index], tuple(body.posed_parents), motions.bone_rotmats_local[span.index, span.slice],
            motions.root_translation_m[span.index, span.slice], motions.fps,
        )
    return [atomic_write_bytes(path, text.encode("utf-8")) for path, text in texts.items()]
