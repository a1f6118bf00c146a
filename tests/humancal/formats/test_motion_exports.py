"""Motion exports (humancal.formats.motions): BVH joints, glTF skinning, npz and OBJ round trips, bad input.

Blender's own reading of the BVH and glTF files is the slow test at the end (scripts/blender_roundtrip.py).
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pygltflib as gl
import pytest
import torch
import trimesh
from scipy.spatial.transform import Rotation

from humancal.body.bones import ANNY_BONES_OF, POSED_BONE_NAMES
from humancal.fitting import FittedMotions
from humancal.formats.errors import FormatError
from humancal.formats.motions import R_YUP_FROM_ZUP, export_motions
from humancal.formats.motions._common import atomic_write_with
from humancal.mocap.bvh import bvh_forward_kinematics, parse_bvh

REPO = Path(__file__).resolve().parents[3]
GLTF_SKINNING_TOLERANCE_M = 5e-4
"""glTF skinning (8 of anny's up to 9 influences per vertex, float32) vs anny's own mesh; measured 0.16 mm."""


def make_motions(num_frames: int = 12, seed: int = 0) -> FittedMotions:
    """Two people; person 7 appears at frame 2, is absent (filled) at frames 5-6 and leaves after frame 9."""
    rng = np.random.default_rng(seed)
    P, T, B = 2, num_frames, len(POSED_BONE_NAMES)
    rotvec = np.cumsum(rng.normal(scale=0.08, size=(P, T, B, 3)), axis=1) + rng.normal(scale=0.3, size=(P, 1, B, 3))
    rotvec[:, :, 0, 2] = np.linspace(0.0, np.radians(450.0), T)  # the root turns 1.25 times about z
    rot = Rotation.from_rotvec(rotvec.reshape(-1, 3)).as_matrix().reshape(P, T, B, 3, 3)
    translation = rng.normal(scale=0.5, size=(P, 1, 3)) + np.cumsum(rng.normal(scale=0.02, size=(P, T, 3)), axis=1)
    present = np.ones((P, T), bool)
    present[1, :2] = present[1, 5:7] = present[1, 10:] = False
    phenotypes = np.array([[0.0, 2 / 3, 0.5, 0.5, 0.3, 0.5], [1.0, 0.8, 0.3, 0.7, 0.2, 0.4]])
    return FittedMotions(np.array([3, 7]), np.arange(500, 500 + T), present, phenotypes, rot, translation,
                         rng.normal(size=(P, T, 23, 3)), 25.0)


@pytest.fixture(scope="module")
def motions() -> FittedMotions:
    return make_motions()


@pytest.fixture(scope="module")
def joints(body_model, motions) -> np.ndarray:
    """(P, T, 22, 3) humancal's posed-bone heads, metres."""
    rest = body_model.rest_skeleton(torch.as_tensor(motions.phenotypes, dtype=body_model.dtype))
    with torch.no_grad():
        return body_model.joints(rest, torch.as_tensor(motions.bone_rotmats_local, dtype=body_model.dtype),
                                 torch.as_tensor(motions.root_translation_m, dtype=body_model.dtype)).double().numpy()


SPANS = {3: (0, 11), 7: (2, 9)}
"""First and last present frame index of each person of :func:`make_motions`."""


# ---------------------------------------------------------------------------------------------------- BVH


def test_bvh_joint_positions_equal_the_body_models_joints(body_model, motions, joints, tmp_path):
    paths = export_motions(motions, body_model, "bvh", tmp_path)
    assert [p.name for p in paths] == ["person_3.bvh", "person_7.bvh"]  # one file per person, gap included
    for p, (path, (first, last)) in enumerate(zip(paths, SPANS.values())):
        parsed = parse_bvh(path)
        assert parsed.values.shape[0] == last - first + 1
        assert parsed.fps == pytest.approx(25.0)
        names = [j.name for j in parsed.joints]
        root = parsed.joints[0]
        assert root.channels[:3] == ("Xposition", "Yposition", "Zposition") and len(root.channels) == 6
        assert all(len(j.channels) == 3 for j in parsed.joints[1:] if not j.is_end_site)
        # The file is Y up: back to humancal's Z-up world.
        positions = bvh_forward_kinematics(parsed) @ R_YUP_FROM_ZUP
        ours = joints[p, first : last + 1]
        theirs = positions[:, [names.index(n) for n in POSED_BONE_NAMES]]
        np.testing.assert_allclose(theirs, ours, atol=1e-5)


def test_bvh_euler_angles_are_continuous(body_model, motions, tmp_path):
    parsed = parse_bvh(export_motions(motions, body_model, "bvh", tmp_path)[0])
    root_yaw = parsed.values[:, 3]  # Yrotation of the root: the file's up axis
    assert root_yaw[-1] - root_yaw[0] == pytest.approx(450.0, abs=30.0)  # unwrapped, not folded into +-180
    # The motion steps about 0.08 rad (~5 deg) per bone per frame; no channel may jump by anything like 360 or 180.
    assert np.abs(np.diff(parsed.values[:, 3:], axis=0)).max() < 90.0


# ---------------------------------------------------------------------------------------------------- glTF


def _accessor(gltf: gl.GLTF2, blob: bytes, index: int) -> np.ndarray:
    accessor = gltf.accessors[index]
    view = gltf.bufferViews[accessor.bufferView]
    dtype = {gl.FLOAT: np.float32, gl.UNSIGNED_BYTE: np.uint8, gl.UNSIGNED_SHORT: np.uint16,
             gl.UNSIGNED_INT: np.uint32}[accessor.componentType]
    width = {gl.SCALAR: 1, gl.VEC3: 3, gl.VEC4: 4, gl.MAT4: 16}[accessor.type]
    data = np.frombuffer(blob, dtype=dtype, count=accessor.count * width, offset=view.byteOffset + (accessor.byteOffset or 0))
    return data.reshape(accessor.count, width) if width > 1 else data


def _trs_matrix(node: gl.Node) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_quat(node.rotation or [0, 0, 0, 1]).as_matrix() * np.array(node.scale or [1, 1, 1])
    matrix[:3, 3] = node.translation or [0, 0, 0]
    return matrix


def test_gltf_one_node_per_person_and_skinning_reproduces_anny(body_model, motions, tmp_path):
    (path,) = export_motions(motions, body_model, "gltf", tmp_path, sequence="seq")
    assert path.name == "seq.glb"
    gltf = gl.GLTF2.load(str(path))
    blob = gltf.binary_blob()
    people = [gltf.nodes[i] for i in gltf.scenes[0].nodes]
    assert [n.name for n in people] == ["person_3", "person_7"]  # one node per person, gap included
    assert len(gltf.skins) == len(gltf.meshes) == 2 and len(gltf.animations) == 1
    animation = gltf.animations[0]
    num_bones = len(body_model.anny_model.bone_labels)
    driven = sum(len(group) for group in ANNY_BONES_OF.values())  # 22 posed bones, toes.* on five bones each
    for p, (person, skin, (first, last)) in enumerate(zip(people, gltf.skins, SPANS.values())):
        assert len(skin.joints) == num_bones
        mesh_node = next(gltf.nodes[c] for c in person.children if gltf.nodes[c].mesh is not None)
        primitive = gltf.meshes[mesh_node.mesh].primitives[0]
        vertices = _accessor(gltf, blob, primitive.attributes.POSITION).astype(np.float64)
        assert vertices.shape == (body_model.num_vertices, 3)
        joint_ids = np.concatenate([_accessor(gltf, blob, primitive.attributes.JOINTS_0),
                                    _accessor(gltf, blob, primitive.attributes.JOINTS_1)], axis=1)
        weights = np.concatenate([_accessor(gltf, blob, primitive.attributes.WEIGHTS_0),
                                  _accessor(gltf, blob, primitive.attributes.WEIGHTS_1)], axis=1).astype(np.float64)
        np.testing.assert_allclose(weights.sum(1), 1.0, atol=1e-6)
        inverse_bind = _accessor(gltf, blob, skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
        # Frame 0 of the person's animation: the first key of every channel, default TRS elsewhere.
        trs = {j: {"rotation": gltf.nodes[j].rotation, "translation": gltf.nodes[j].translation} for j in skin.joints}
        channels = [c for c in animation.channels if c.target.node in trs]
        assert sum(c.target.path == "rotation" for c in channels) == driven
        for c in channels:
            sampler = animation.samplers[c.sampler]
            keys = _accessor(gltf, blob, sampler.output)
            times = _accessor(gltf, blob, sampler.input)
            assert len(keys) == len(times) == last - first + 1
            np.testing.assert_allclose(times[0], first / motions.fps, atol=1e-6)
            trs[c.target.node][c.target.path] = [float(v) for v in keys[0]]
        nodes = {j: _trs_matrix(gl.Node(**values)) for j, values in trs.items()}
        # Global joint transforms (the person node's Y-up rotation left out: humancal's world), then LBS.
        parent_of = {child: j for j in skin.joints for child in gltf.nodes[j].children}
        world = {}
        for j in skin.joints:  # parents before children (anny's bone order)
            world[j] = world[parent_of[j]] @ nodes[j] if j in parent_of else nodes[j]
        transforms = np.stack([world[j] for j in skin.joints]) @ inverse_bind
        homogeneous = np.concatenate([vertices, np.ones((len(vertices), 1))], axis=1)
        skinned = np.einsum("vk,vkij,vj->vi", weights, transforms[joint_ids.astype(int)], homogeneous)[:, :3]
        with torch.no_grad():
            reference = body_model.reference_forward(
                torch.as_tensor(motions.phenotypes[p : p + 1], dtype=body_model.dtype),
                torch.as_tensor(motions.bone_rotmats_local[p : p + 1, first : first + 1], dtype=body_model.dtype),
                torch.as_tensor(motions.root_translation_m[p : p + 1, first : first + 1], dtype=body_model.dtype),
            )["vertices"][0, 0].double().numpy()
        error = np.linalg.norm(skinned - reference, axis=1).max()
        assert error < GLTF_SKINNING_TOLERANCE_M, f"person {p}: max vertex error {error * 1e3:.3f} mm"
    # Person 7 is hidden outside their span: a STEP scale 0 -> 1 -> 0 on their node.
    scale = [c for c in animation.channels if c.target.node == gltf.scenes[0].nodes[1] and c.target.path == "scale"]
    sampler = animation.samplers[scale[0].sampler]
    assert sampler.interpolation == "STEP"
    np.testing.assert_allclose(_accessor(gltf, blob, sampler.input), np.array([0, 2, 10]) / motions.fps, atol=1e-6)
    np.testing.assert_allclose(_accessor(gltf, blob, sampler.output)[:, 0], [0, 1, 0])


# ---------------------------------------------------------------------------------------------------- npz, obj


def test_npz_round_trip(body_model, motions, joints, tmp_path):
    (path,) = export_motions(motions, body_model, "npz", tmp_path, sequence="seq")
    with np.load(path) as data:  # no pickle needed
        for name in ("person_ids", "frames", "present", "phenotypes", "bone_rotmats_local", "root_translation_m",
                     "keypoints_world_m"):
            np.testing.assert_array_equal(data[name], getattr(motions, name), err_msg=name)
        assert float(data["fps"]) == motions.fps
        assert tuple(data["bone_names"]) == POSED_BONE_NAMES
        np.testing.assert_allclose(data["joints_world_m"], joints, atol=1e-9)
        assert "Z up" in str(data["conventions"])


def test_obj_meshes_per_person_and_frame(body_model, motions, tmp_path):
    done = []
    paths = export_motions(motions, body_model, "obj", tmp_path, frames=slice(502, 506, 3), progress=done.append)
    assert sorted(p.relative_to(tmp_path).as_posix() for p in paths) == [
        "person_3/frame_000502.obj", "person_3/frame_000505.obj", "person_7/frame_000502.obj",
        "person_7/frame_000505.obj"]
    assert sum(done) == 4
    mesh = trimesh.load(tmp_path / "person_7/frame_000505.obj", process=False)
    with torch.no_grad():
        reference = body_model.reference_forward(
            torch.as_tensor(motions.phenotypes[1:2], dtype=body_model.dtype),
            torch.as_tensor(motions.bone_rotmats_local[1:2, 5:6], dtype=body_model.dtype),
            torch.as_tensor(motions.root_translation_m[1:2, 5:6], dtype=body_model.dtype))["vertices"][0, 0].numpy()
    np.testing.assert_allclose(mesh.vertices, reference, atol=1e-6)
    assert len(mesh.faces) == len(body_model.faces)


# ---------------------------------------------------------------------------------------------------- bad input


def test_bad_rotations_name_the_field_and_write_nothing(body_model, motions, tmp_path):
    rot = motions.bone_rotmats_local.copy()
    rot[1, 4, 7] *= 1.5
    bad = FittedMotions(motions.person_ids, motions.frames, motions.present, motions.phenotypes, rot,
                        motions.root_translation_m, motions.keypoints_world_m, motions.fps)
    for fmt in ("bvh", "gltf", "npz", "obj"):
        with pytest.raises(FormatError, match=r"FittedMotions.bone_rotmats_local.*rotation matrices.*person 7, frame 504, bone foot.L"):
            export_motions(bad, body_model, fmt, tmp_path / fmt)
        assert not (tmp_path / fmt).exists() or not any((tmp_path / fmt).rglob("*"))


def test_bad_arguments(body_model, motions, tmp_path):
    with pytest.raises(FormatError, match="field 'format': expected one of bvh, gltf, npz, obj, got 'fbx'"):
        export_motions(motions, body_model, "fbx", tmp_path)
    with pytest.raises(FormatError, match="field 'motions': expected a humancal.fitting.FittedMotions"):
        export_motions({"person_ids": []}, body_model, "bvh", tmp_path)
    with pytest.raises(FormatError, match="field 'frames'"):
        export_motions(motions, body_model, "bvh", tmp_path, frames=slice(0, 5))
    nan = motions.root_translation_m.copy()
    nan[0, 3, 1] = np.nan
    bad = FittedMotions(motions.person_ids, motions.frames, motions.present, motions.phenotypes,
                        motions.bone_rotmats_local, nan, motions.keypoints_world_m, motions.fps)
    with pytest.raises(FormatError, match=r"FittedMotions.root_translation_m': expected finite numbers.*\[0, 3, 1\]"):
        export_motions(bad, body_model, "npz", tmp_path)
    assert not any(tmp_path.iterdir())


def test_failed_write_leaves_the_previous_file_and_no_temporary(tmp_path):
    path = tmp_path / "person_3.bvh"
    path.write_text("previous")

    def fail(handle):
        handle.write(b"half")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        atomic_write_with(path, fail)
    assert path.read_text() == "previous" and [p.name for p in tmp_path.iterdir()] == ["person_3.bvh"]


# ---------------------------------------------------------------------------------------------------- Blender


@pytest.mark.slow
def test_blender_imports_bvh_and_gltf_within_a_millimetre(tmp_path):
    if shutil.which("blender") is None:
        pytest.skip("no `blender` on PATH (Debian/Ubuntu: apt-get install blender python3-numpy)")
    summary = tmp_path / "summary.json"
    run = subprocess.run([sys.executable, str(REPO / "scripts" / "blender_roundtrip.py"), "--json", str(summary)],
                         capture_output=True, text=True, timeout=900, cwd=REPO)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-4000:]
    import json

    errors = json.loads(summary.read_text())["max_joint_error_m"]
    assert errors["bvh"] <= 1e-3 and errors["gltf"] <= 1e-3 and errors["gltf_mesh"] <= 1e-3
