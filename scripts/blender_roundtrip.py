"""Blender round trip of the motion exports: write a fitted motion to BVH and glTF, import both in Blender,
read the armatures' bone heads back and compare them with humancal's joints (max error must be <= 1 mm).

    python scripts/blender_roundtrip.py [--blender blender] [--frames 60] [--keep DIR] [--json FILE]

The motion is synthetic (two people, smooth swings of every posed bone with some large angles: 120 deg knees,
arms raised past horizontal, a root yaw of 450 deg over the clip, a walk); the second person appears late,
leaves for a few frames in the middle (``present`` False, values filled) and leaves before the end. Blender
imports each file with its default axis options (BVH: forward -Z, up Y, scale 1; glTF: +Y up), and the world
head of every pose bone (``armature.matrix_world @ pose_bone.head``) is read at every frame of each person's
span. Prints the Blender version and the max errors; exits 1 when one exceeds the tolerance, 2 without Blender.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from humancal.body import BodyModel
from humancal.body.bones import ANNY_BONES_OF, POSED_BONE_NAMES
from humancal.fitting import FittedMotions
from humancal.formats.motions import export_motions

TOLERANCE_M = 1e-3
MESH_TOLERANCE_M = 1e-3
"""Blender's skinned glTF mesh vs anny's (8 of anny's up to 9 influences kept: see docs/formats.md)."""

INNER = r'''
import builtins, bpy, json, sys
# Debian's Blender 3.4 runs on Python 3.11, where its BVH importer's open(path, "rU") fails: drop the "U".
import io_anim_bvh.import_bvh as _import_bvh
_import_bvh.open = lambda path, mode="r", *args, **kwargs: builtins.open(path, mode.replace("U", ""), *args, **kwargs)
# ... and its glTF importer uses np.bool, which numpy >= 1.24 removed.
import numpy
if "bool" not in numpy.__dict__:
    numpy.bool = bool
config = json.load(open(sys.argv[sys.argv.index("--") + 1]))
bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.fps, scene.render.fps_base = int(config["fps"]), 1.0
out = {"version": bpy.app.version_string, "bvh": {}, "gltf": {}}

def heads(armature, frames):
    rows = []
    for frame in frames:
        scene.frame_set(frame)
        rows.append({b.name: list(armature.matrix_world @ b.head) for b in armature.pose.bones})
    return rows

for item in config["bvh"]:
    before = set(bpy.data.objects)
    bpy.ops.import_anim.bvh(filepath=item["path"], frame_start=1, use_fps_scale=False, update_scene_fps=False,
                            update_scene_duration=True, rotate_mode="NATIVE", axis_forward="-Z", axis_up="Y",
                            global_scale=1.0)
    armature = [o for o in bpy.data.objects if o not in before and o.type == "ARMATURE"][0]
    out["bvh"][str(item["person_id"])] = heads(armature, [1 + k for k in range(item["num_frames"])])

bpy.ops.wm.read_factory_settings(use_empty=True)
scene = bpy.context.scene
scene.render.fps, scene.render.fps_base = int(config["fps"]), 1.0
bpy.ops.import_scene.gltf(filepath=config["gltf"])
for armature in [o for o in bpy.data.objects if o.type == "ARMATURE"]:
    owner, person = armature, None
    while owner is not None and person is None:
        if owner.name.startswith("person_") and owner.name[7:].isdigit():
            person = owner.name[7:]
        owner = owner.parent
    item = config["gltf_people"][person]
    # Blender keys glTF time t at frame t * fps + offset: find the offset from the root's first key.
    action = armature.animation_data.action
    keyed = [k.co[0] for c in action.fcurves if c.data_path == 'pose.bones["root"].location' for k in c.keyframe_points]
    offset = round(min(keyed)) - item["first"]
    record = {"offset": offset,
              "heads": heads(armature, [offset + item["first"] + k for k in range(item["num_frames"])])}
    # The skinned mesh as Blender deforms it, at the span's middle frame (world coordinates, vertex order kept).
    scene.frame_set(offset + item["first"] + item["num_frames"] // 2)
    mesh_object = [o for o in bpy.data.objects if o.type == "MESH" and o.find_armature() == armature][0]
    evaluated = mesh_object.evaluated_get(bpy.context.evaluated_depsgraph_get())
    record["mesh_middle"] = [list(evaluated.matrix_world @ v.co) for v in evaluated.to_mesh().vertices]
    # Hidden before the first present frame: the world scale of the armature there.
    if item["first"] > 0:
        scene.frame_set(offset + item["first"] - 1)
        record["scale_before"] = max(abs(x) for x in armature.matrix_world.to_scale())
    out["gltf"][person] = record
json.dump(out, open(config["out"], "w"))
'''


def synthetic_motions(num_frames: int, fps: float = 30.0, seed: int = 0) -> FittedMotions:
    """Two people, smooth plausible-range motion with some large angles; person 7 appears late, has a gap."""
    rng = np.random.default_rng(seed)
    P, T, B = 2, num_frames, len(POSED_BONE_NAMES)
    s = np.arange(T) / fps
    phase = rng.uniform(0, 2 * np.pi, size=(P, 1, B, 3))
    freq = rng.uniform(0.3, 1.2, size=(P, 1, B, 3))
    rotvec = 0.35 * np.sin(2 * np.pi * freq * s[None, :, None, None] + phase)
    index = {name: b for b, name in enumerate(POSED_BONE_NAMES)}
    wave = 0.5 - 0.5 * np.cos(2 * np.pi * s / max(s[-1], 1e-9))  # 0 -> 1 -> 0 over the clip
    for side in ("L", "R"):
        rotvec[:, :, index[f"lowerleg01.{side}"], 0] += 2.1 * wave  # knees up to 120 deg
        rotvec[:, :, index[f"upperleg01.{side}"], 0] -= 1.4 * wave  # hips flexed 80 deg (sitting)
    rotvec[:, :, index["upperarm01.L"], 1] -= 2.0 * wave  # raise the left arm past horizontal
    rotvec[:, :, index["upperarm01.R"], 0] -= 2.2 * wave  # right arm forward and up
    rot = Rotation.from_rotvec(rotvec.reshape(-1, 3)).as_matrix().reshape(P, T, B, 3, 3)
    yaw = Rotation.from_euler("z", np.linspace(0, np.radians(450), T)[:, None]).as_matrix()  # turn 1.25 times
    rot[:, :, 0] = yaw[None] @ rot[:, :, 0]
    translation = np.stack([np.stack([0.8 * s + p, 0.3 * np.sin(s + p), 0.95 + 0.02 * np.sin(5 * s)], -1)
                            for p in range(P)])
    present = np.ones((P, T), bool)
    present[1, : T // 6] = False
    present[1, T // 2 : T // 2 + 4] = False
    present[1, -T // 8 :] = False
    phenotypes = np.array([[0.0, 2 / 3, 0.5, 0.5, 0.3, 0.5], [1.0, 0.8, 0.3, 0.7, 0.2, 0.4]])
    return FittedMotions(person_ids=np.array([3, 7]), frames=np.arange(1000, 1000 + T), present=present,
                         phenotypes=phenotypes, bone_rotmats_local=rot, root_translation_m=translation,
                         keypoints_world_m=np.zeros((P, T, 23, 3)), fps=fps)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--blender", default="blender", help="Blender executable (default: blender on PATH)")
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--keep", type=Path, help="write the files here and keep them (default: a temporary folder)")
    parser.add_argument("--json", type=Path, help="also write the errors as JSON here")
    args = parser.parse_args(argv)
    blender = shutil.which(args.blender)
    if blender is None:
        print(f"blender_roundtrip: no Blender executable {args.blender!r} on PATH", file=sys.stderr)
        return 2
    torch.set_num_threads(1)
    body = BodyModel()
    motions = synthetic_motions(args.frames)
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        bvh_files = export_motions(motions, body, "bvh", folder)
        gltf_file = export_motions(motions, body, "gltf", folder, sequence="roundtrip")[0]
        rest = body.rest_skeleton(torch.as_tensor(motions.phenotypes, dtype=body.dtype))
        joints = body.joints(rest, torch.as_tensor(motions.bone_rotmats_local, dtype=body.dtype),
                             torch.as_tensor(motions.root_translation_m, dtype=body.dtype)).double().numpy()
        spans = {}
        for p, person_id in enumerate(motions.person_ids.tolist()):
            present = np.flatnonzero(motions.present[p])
            spans[str(person_id)] = {"first": int(present[0]), "num_frames": int(present[-1] - present[0] + 1)}
        config = {
            "fps": motions.fps, "out": str(Path(folder) / "blender_heads.json"), "gltf": str(gltf_file),
            "bvh": [{"person_id": pid, "path": str(path), "num_frames": spans[str(pid)]["num_frames"]}
                    for pid, path in zip(motions.person_ids.tolist(), bvh_files)],
            "gltf_people": spans,
        }
        config_path = Path(folder) / "blender_config.json"
        config_path.write_text(json.dumps(config))
        start = time.perf_counter()
        run = subprocess.run([blender, "-b", "--factory-startup", "--python-expr", INNER, "--", str(config_path)],
                             capture_output=True, text=True, timeout=600)
        if run.returncode != 0 or not Path(config["out"]).exists():
            print(run.stdout[-3000:], run.stderr[-3000:], file=sys.stderr)
            print("blender_roundtrip: Blender failed", file=sys.stderr)
            return 1
        result = json.loads(Path(config["out"]).read_text())
    errors = {"bvh": 0.0, "gltf": 0.0}
    gltf_names = {name: ANNY_BONES_OF[name][0] for name in POSED_BONE_NAMES}  # toes.L -> toe1-1.L
    for p, person_id in enumerate(motions.person_ids.tolist()):
        span = spans[str(person_id)]
        ours = joints[p, span["first"] : span["first"] + span["num_frames"]]
        for fmt, rows, names in (("bvh", result["bvh"][str(person_id)], {n: n for n in POSED_BONE_NAMES}),
                                 ("gltf", result["gltf"][str(person_id)]["heads"], gltf_names)):
            theirs = np.array([[row[names[n]] for n in POSED_BONE_NAMES] for row in rows])
            errors[fmt] = max(errors[fmt], float(np.abs(np.linalg.norm(theirs - ours, axis=-1)).max()))
    # Blender's deformation of the glTF mesh vs anny's own skinned mesh, at each person's middle frame.
    mesh_error, hidden_scale = 0.0, 0.0
    for p, person_id in enumerate(motions.person_ids.tolist()):
        record, span = result["gltf"][str(person_id)], spans[str(person_id)]
        t = span["first"] + span["num_frames"] // 2
        with torch.no_grad():
            ref = body.reference_forward(
                torch.as_tensor(motions.phenotypes[p : p + 1], dtype=body.dtype),
                torch.as_tensor(motions.bone_rotmats_local[p : p + 1, t : t + 1], dtype=body.dtype),
                torch.as_tensor(motions.root_translation_m[p : p + 1, t : t + 1], dtype=body.dtype))["vertices"]
        mesh_error = max(mesh_error, float(np.linalg.norm(np.array(record["mesh_middle"]) - ref[0, 0].double().numpy(),
                                                          axis=-1).max()))
        hidden_scale = max(hidden_scale, record.get("scale_before", 0.0))
    errors["gltf_mesh"] = mesh_error
    summary = {"hidden_world_scale_before_first_frame": hidden_scale, "blender_version": result["version"], "max_joint_error_m": errors, "tolerance_m": TOLERANCE_M,
               "frames": args.frames, "people": len(spans), "blender_s": round(time.perf_counter() - start, 1),
               "gltf_frame_offset": {pid: v["offset"] for pid, v in result["gltf"].items()}}
    print(f"Blender {result['version']}: max joint error BVH {errors['bvh'] * 1e3:.4f} mm, "
          f"glTF {errors['gltf'] * 1e3:.4f} mm, glTF mesh vertices vs anny {mesh_error * 1e3:.3f} mm "
          f"(hidden person's scale before their first frame: {hidden_scale:g}) (joint tolerance {TOLERANCE_M * 1e3:g} mm; {len(spans)} people, "
          f"{args.frames} frames)")
    if args.json:
        args.json.write_text(json.dumps(summary, indent=2))
    ok = max(errors["bvh"], errors["gltf"]) <= TOLERANCE_M and mesh_error <= MESH_TOLERANCE_M and hidden_scale == 0.0
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
