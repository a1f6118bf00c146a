"""How much a lifter tilts the poses it lifts, by the camera's pitch: the rotation that best aligns each lifted pose
with the true one in the camera frame (a per-pose Procrustes rotation, centroids removed), averaged by pitch band.

A lifter that sees a person from above the way it was trained should give a mean rotation near zero; a systematic
rotation about the camera's x axis is a tilt towards or away from the camera, which the calibration's lifted-shape
term turns into camera angles (every view of a steep rig off by the same few degrees). The scenes are those of the
stress sweep (``scripts/stress_sweep.py``), with their camera drawing (ordinary, steep, near the horizon); the
truth is used for the figures only.

    python scripts/lifter_tilt.py --scenes 0-23 --lifters shipped,/tmp/seeds/lifter_seed1.pt
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

PITCH_BANDS_DEG = (-10.0, 15.0, 30.0, 45.0, 60.0, 80.0)


def _scene_indices(text: str) -> list[int]:
    if "-" in text:
        first, last = (int(x) for x in text.split("-"))
        return list(range(first, last + 1))
    return [int(x) for x in text.split(",")]


def scene_tilts(scene, lifter) -> pd.DataFrame:
    """One row per lifted detection of a true person: the camera's pitch below the horizon at that person
    (degrees) and the rotation vector (degrees, camera axes) that aligns the lifted pose with the truth."""
    from humancal.geometry.alignment import fit_similarity
    from humancal.lifter import lift_detections
    from humancal.tables.detections import detections_to_dense

    dense = detections_to_dense(scene.detections)
    lifted = lift_detections(lifter, dense.keypoints_px, dense.scores)
    if lifted.frame == "crop":
        lifted = lifted.in_camera_frame(np.stack([c.K for c in scene.rig])[dense.view])
    person = {(f, v, d): p for f, v, d, p in scene.associations[["frame", "view", "det_id", "person_id"]]
              .itertuples(index=False)}
    truth = {(f, p): np.asarray(k).reshape(-1, 3)
             for f, p, k in scene.motions[["frame", "person_id", "keypoints_world_m"]].itertuples(index=False)}
    rows = []
    for d in np.flatnonzero(lifted.valid):
        pid = person.get((dense.frame[d], dense.view[d], dense.det_id[d]), -1)
        joints_world = truth.get((dense.frame[d], pid))
        if pid < 0 or joints_world is None:
            continue
        camera = scene.rig[int(dense.view[d])]
        joints_cam = joints_world @ camera.R_cam_from_world.T + camera.t_cam_from_world_m
        offset = camera.center_world_m - joints_world.mean(0)
        pitch = np.degrees(np.arctan2(offset[2], np.hypot(offset[0], offset[1])))
        ok = np.isfinite(lifted.joints_cam_m[d]).all(1)  # the rigid motion taking the lifted pose onto the truth
        rotation = fit_similarity(lifted.joints_cam_m[d][ok], joints_cam[ok], with_scale=False).R
        rotvec = Rotation.from_matrix(rotation).as_rotvec(degrees=True)
        rows.append({"pitch_deg": pitch, "rot_x_deg": rotvec[0], "rot_y_deg": rotvec[1], "rot_z_deg": rotvec[2]})
    return pd.DataFrame(rows)


def tilt_table(tilts: pd.DataFrame) -> pd.DataFrame:
    """Per lifter and pitch band: detections, the mean rotation about each camera axis and the median angle."""
    bands = pd.cut(tilts["pitch_deg"], PITCH_BANDS_DEG)
    angle = np.linalg.norm(tilts[["rot_x_deg", "rot_y_deg", "rot_z_deg"]].to_numpy(), axis=1)
    grouped = tilts.assign(band=bands, angle_deg=angle).groupby(["lifter", "band"], observed=True)
    return grouped.agg(detections=("angle_deg", "size"), mean_rot_x_deg=("rot_x_deg", "mean"),
                       mean_rot_y_deg=("rot_y_deg", "mean"), mean_rot_z_deg=("rot_z_deg", "mean"),
                       median_angle_deg=("angle_deg", "median")).round(2).reset_index()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default="0-23", help="stress-sweep scene indices: 'a-b' or 'i,j,k'")
    parser.add_argument("--lifters", default="shipped", help="comma-separated: 'shipped' or checkpoint paths")
    parser.add_argument("--seed", type=int, default=0, help="the stress sweep's seed")
    parser.add_argument("--out", type=Path, default=None, help="CSV of the table (printed either way)")
    args = parser.parse_args()
    import stress_sweep

    from humancal.synthetic import generate_scene

    specs = [s.strip() for s in args.lifters.split(",") if s.strip()]
    stress_sweep._init_worker(specs)
    body = stress_sweep._WORKER["body"]
    scenes = [generate_scene(stress_sweep.scene_config(i, args.seed)[0], body, sequence=f"stress_{i}")
              for i in _scene_indices(args.scenes)]
    parts = [scene_tilts(scene, lifter).assign(lifter=spec)
             for spec, (_, lifter) in zip(specs, stress_sweep._WORKER["lifters"]) for scene in scenes]
    table = tilt_table(pd.concat(parts, ignore_index=True))
    print(table.to_markdown(index=False))
    if args.out:
        table.to_csv(args.out, index=False)


if __name__ == "__main__":
    main()
