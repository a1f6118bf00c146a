"""Fitted motions to one binary glTF (.glb) per sequence: each person's anny mesh, skinned and animated.

Layout: per person a node ``person_<id>`` (its rotation turns humancal's Z-up world into glTF's Y up, see
``R_YUP_FROM_ZUP``) holding anny's 104-bone skeleton (joint nodes named by anny's bone labels) and a node
``person_<id>_mesh`` with the person's anny mesh (rest shape of their phenotypes) skinned to it. One animation,
``motions``: a rotation channel per posed bone (22, the ``toes.*`` rotation on each of its five toe bones) and a
translation channel on ``root``, one key per frame of the person's first..last present frame, at the sequence's
time ``(frame - first frame of the sequence) / fps`` seconds (LINEAR; rotations SLERP). Outside a person's span
the person is **hidden**: a STEP scale channel on ``person_<id>`` is 0 before their first and after their last
present frame (and the pose holds the nearest keyed frame).

Skinning is anny's own linear blend skinning, with the largest 8 of anny's up to 9 influences per vertex
(two sets, JOINTS_0/WEIGHTS_0 and JOINTS_1/WEIGHTS_1, renormalised): the vertices then differ from
``BodyModel.reference_forward`` by less than the tolerance stated in ``docs/formats.md``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pygltflib as gl
import trimesh

from humancal.body import BodyModel
from humancal.fitting import FittedMotions
from humancal.formats.motions._common import (
    R_YUP_FROM_ZUP,
    PersonSpan,
    atomic_write_bytes,
    check_motions,
    person_spans,
)
from humancal.formats.motions._glb import GlbBuilder
from humancal.geometry.rotations import rotmat_to_quat_xyzw
from humancal.formats.motions.rig import (
    PersonRig,
    animated_bones,
    bone_world_poses,
    local_transforms,
    person_rig,
    skin_weights,
)

__all__ = ["MAX_INFLUENCES", "write_gltf"]

MAX_INFLUENCES = 8
"""Skinning influences kept per vertex (two glTF sets of 4)."""


def _quaternions_xyzw(rotmats: np.ndarray) -> np.ndarray:
    """(..., 3, 3) -> (..., 4) unit quaternions (x, y, z, w), sign-continuous along axis 0 for SLERP."""
    quat = rotmat_to_quat_xyzw(rotmats.reshape(-1, 3, 3)).reshape(rotmats.shape[:-2] + (4,))
    for t in range(1, quat.shape[0]):
        flip = (quat[t] * quat[t - 1]).sum(-1) < 0.0
        quat[t][flip] *= -1.0
    return quat


def _trs(matrix: np.ndarray) -> dict[str, list[float]]:
    return {
        "translation": [float(v) for v in matrix[:3, 3]],
        "rotation": [float(v) for v in rotmat_to_quat_xyzw(matrix[:3, :3])],
    }


def _add_mesh(builder: GlbBuilder, rig: PersonRig, faces: np.ndarray, joints: np.ndarray, weights: np.ndarray) -> int:
    vertices = rig.rest_vertices_m.astype(np.float32)
    normals = trimesh.Trimesh(rig.rest_vertices_m, faces, process=False).vertex_normals.astype(np.float32)
    index_type = np.uint16 if len(vertices) < 65535 else np.uint32
    attributes = gl.Attributes(
        POSITION=builder.add_accessor(vertices, target=gl.ARRAY_BUFFER, min_max=True),
        NORMAL=builder.add_accessor(normals, target=gl.ARRAY_BUFFER),
    )
    for k in range(MAX_INFLUENCES // 4):
        setattr(attributes, f"JOINTS_{k}", builder.add_accessor(joints[:, 4 * k : 4 * k + 4], target=gl.ARRAY_BUFFER))
        setattr(attributes, f"WEIGHTS_{k}", builder.add_accessor(weights[:, 4 * k : 4 * k + 4], target=gl.ARRAY_BUFFER))
    indices = builder.add_accessor(faces.reshape(-1).astype(index_type), target=gl.ELEMENT_ARRAY_BUFFER)
    builder.gltf.meshes.append(gl.Mesh(primitives=[gl.Primitive(attributes=attributes, indices=indices)]))
    return len(builder.gltf.meshes) - 1


def _add_person(
    builder: GlbBuilder,
    animation: gl.Animation,
    body: BodyModel,
    motions: FittedMotions,
    span: PersonSpan,
    skin: tuple[np.ndarray, np.ndarray],
    faces: np.ndarray,
) -> None:
    rig = person_rig(body, motions.phenotypes[span.index])
    # Joint nodes in anny's bone order; each node's default transform is the reference pose.
    first_joint = len(builder.gltf.nodes)
    for j, name in enumerate(rig.bone_names):
        builder.add_node(gl.Node(name=name, **_trs(rig.reference_local[j])))
    for j, parent in enumerate(rig.parents):
        if parent >= 0:
            builder.gltf.nodes[first_joint + parent].children.append(first_joint + j)
    inverse_bind = np.ascontiguousarray(rig.inverse_bind.transpose(0, 2, 1)).reshape(-1, 16).astype(np.float32)
    builder.gltf.skins.append(gl.Skin(
        name=f"person_{span.person_id}_skeleton", joints=list(range(first_joint, first_joint + len(rig.bone_names))),
        inverseBindMatrices=builder.add_accessor(inverse_bind), skeleton=first_joint,
    ))
    mesh_node = builder.add_node(gl.Node(name=f"person_{span.person_id}_mesh", mesh=_add_mesh(builder, rig, faces, *skin),
                                         skin=len(builder.gltf.skins) - 1))
    person_node = builder.add_node(gl.Node(
        name=f"person_{span.person_id}", children=[first_joint, mesh_node],
        rotation=[float(v) for v in rotmat_to_quat_xyzw(R_YUP_FROM_ZUP)],
    ))
    builder.gltf.scenes[0].nodes.append(person_node)

    # Animation: one key per frame of the span, at the sequence's time.
    times_s = (motions.frames - motions.frames[0]) / motions.fps
    world = bone_world_poses(body, rig, motions.bone_rotmats_local[span.index, span.slice],
                             motions.root_translation_m[span.index, span.slice])
    local = local_transforms(world, rig.parents)
    time_accessor = builder.add_accessor(times_s[span.slice].astype(np.float32), min_max=True)

    def channel(node: int, path: str, values: np.ndarray, times: int = time_accessor, step: bool = False) -> None:
        animation.samplers.append(gl.AnimationSampler(
            input=times, output=builder.add_accessor(values.astype(np.float32)), interpolation="STEP" if step else "LINEAR"
        ))
        animation.channels.append(gl.AnimationChannel(
            sampler=len(animation.samplers) - 1, target=gl.AnimationChannelTarget(node=node, path=path)
        ))

    for j in animated_bones(rig.bone_names):
        channel(first_joint + j, "rotation", _quaternions_xyzw(local[:, j, :3, :3]))
    channel(first_joint, "translation", local[:, 0, :3, 3])
    # Hidden outside the span: scale 0 before the first and after the last present frame (STEP).
    keys, scales = [], []
    if span.first > 0:
        keys, scales = [0.0], [0.0]
    keys.append(times_s[span.first]), scales.append(1.0)
    if span.last < motions.num_frames - 1:
        keys.append(times_s[span.last + 1]), scales.append(0.0)
    if len(keys) > 1:
        key_accessor = builder.add_accessor(np.array(keys, dtype=np.float32), min_max=True)
        channel(person_node, "scale", np.repeat(np.array(scales)[:, None], 3, axis=1), key_accessor, step=True)


def gltf_file_name(sequence: str | None) -> str:
    """The file name of a sequence's glTF: ``<sequence>.glb`` (``motions.glb`` without a name)."""
    return f"{sequence or 'motions'}.glb"


def write_gltf(motions: FittedMotions, body: BodyModel, out_dir: str | Path, sequence: str | None = None) -> list[Path]:
    """Write ``<out_dir>/<sequence>.glb``: every person's skinned anny mesh, animated at ``motions.fps``.

    Args:
        motions: the fitted motions.
        body: the body model (anny's mesh, rig and weights).
        out_dir: output folder (created when missing).
        sequence: names the file (default ``motions.glb``).

    Returns:
        ``[path]`` of the file written.

    Raises:
        FormatError: bad motions (see ``check_motions``); nothing is written then (the file is written
            atomically, after everything is built).
    """
    motions = check_motions(motions)
    joints, weights, _ = skin_weights(body, MAX_INFLUENCES)
    faces = body.faces.cpu().numpy()
    builder = GlbBuilder(generator="humancal (anny body model)")
    animation = gl.Animation(name="motions", samplers=[], channels=[])
    for span in person_spans(motions):
        _add_person(builder, animation, body, motions, span, (joints, weights), faces)
    builder.gltf.animations.append(animation)
    builder.gltf.extras = {
        "humancal": {
            "person_ids": [int(p) for p in motions.person_ids], "first_frame": int(motions.frames[0]),
            "fps": float(motions.fps), "world": "glTF Y up, metres; humancal world = R_YUP_FROM_ZUP^T @ glTF",
        }
    }
    return [atomic_write_bytes(Path(out_dir) / gltf_file_name(sequence), builder.to_bytes())]
