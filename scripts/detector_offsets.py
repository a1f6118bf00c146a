"""Where a sequence's detector puts each keypoint, against the body model's keypoint (a diagnostic: known cameras).

The body fit compares the detections with anny's 23 canonical keypoints. A real detector was trained on its own
annotations: its hip, ankle or ear may sit a little away from the body model's, for everyone and always. This
script measures that on a sequence whose cameras are known: it associates the detections with the known cameras,
fits the bodies with the cameras held (the default fit settings), and expresses, per keypoint, the median offset
from the fitted body's keypoint to the triangulated joint in the axes of the keypoint's dominant bone (the
reference pose's axes: X to the body's left, Y to its back, Z up; ``RestSkeleton.with_keypoint_offsets``). The rms
column is the whole spread (pose errors, noise and offset together).

Reads the ``detections`` and ``gt_cameras`` tables of a materialized partition (``humancal update --partition P``
first). On synthetic scenes with ``DetectorNoise.keypoint_bias_m`` the offsets are known and this shows how much
of them a fit with known cameras sees.

    python scripts/detector_offsets.py --partition shelf__test [--state-dir DIR]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
import torch

from humancal.association import associate, to_associations_table, to_skeletons_table
from humancal.body import BodyModel
from humancal.camera import CameraRig, cameras_from_table
from humancal.fitting import BodyFitConfig, body_observations, fit_bodies
from humancal.keypoints import CANONICAL_JOINTS
from humancal.lifter import lifted_from_table
from humancal.prior import shipped_prior
from humancal.settings import state_dir


def _table(root: Path, asset: str, partition: str) -> pd.DataFrame:
    path = root / "artifacts" / asset / f"{partition}.parquet"
    if not path.is_file():
        raise SystemExit(f"{path} does not exist: materialize the partition first (humancal update --partition "
                         f"{partition})")
    return pd.read_parquet(path)


def keypoint_offsets_table(root: Path, partition: str, fps: float) -> pd.DataFrame:
    """Per keypoint: detections, the median offset (mm, bone axes), its norm and the rms distance (mm)."""
    dense, lifted = lifted_from_table(_table(root, "detections", partition))
    cameras = cameras_from_table(_table(root, "gt_cameras", partition))
    if not cameras:
        raise SystemExit(f"{partition}: no known cameras (gt_cameras is empty): the diagnostic needs them")
    rig = CameraRig.from_cameras(cameras)
    association = associate(dense, lifted, rig)
    observations, _ = body_observations(dense, to_associations_table(association, partition),
                                        to_skeletons_table(association, partition), len(cameras))
    body = BodyModel()
    fit = fit_bodies(body, observations, rig, shipped_prior()[0], BodyFitConfig(cameras="fixed"), fps=fps)
    motions = fit.motions
    rest = body.rest_skeleton(torch.as_tensor(motions.phenotypes, dtype=body.dtype))
    with torch.no_grad():
        rotations = body.bone_world_rotations(rest, torch.as_tensor(motions.bone_rotmats_local, dtype=body.dtype),
                                              torch.as_tensor(motions.root_translation_m, dtype=body.dtype))
    dominant = rest.dominant_bones()[0].numpy()  # the same for every shape
    frames = np.searchsorted(motions.frames, observations.frames)
    bone_rotations = rotations.double().numpy()[:, frames][:, :, dominant]  # (P, T, 23, 3, 3)
    difference = observations.joints_world_m - motions.keypoints_world_m[:, frames]
    valid = observations.joints_valid & motions.present[:, frames][..., None]
    in_bone = np.einsum("ptkji,ptkj->ptki", bone_rotations, difference)  # G^T d: the offset in the bone's axes
    rows = []
    for k, name in enumerate(CANONICAL_JOINTS):
        seen = in_bone[..., k, :][valid[..., k]]
        median = 1000 * np.median(seen, axis=0) if len(seen) else np.full(3, np.nan)
        rows.append({"keypoint": name, "joints": len(seen), "x_mm": median[0], "y_mm": median[1], "z_mm": median[2],
                     "median_norm_mm": float(np.linalg.norm(median)),
                     "rms_mm": float(1000 * np.sqrt((seen**2).sum(-1).mean())) if len(seen) else np.nan})
    return pd.DataFrame(rows).set_index("keypoint")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--partition", required=True)
    parser.add_argument("--state-dir", type=Path, default=None, help="default: the project's state dir")
    parser.add_argument("--fps", type=float, default=25.0, help="the sequence's frame rate (default 25)")
    args = parser.parse_args()
    table = keypoint_offsets_table(args.state_dir or state_dir(), args.partition, args.fps)
    print(table.to_markdown(floatfmt=".1f"))
    print(f"median over keypoints of the offset's norm: {table['median_norm_mm'].median():.1f} mm")


if __name__ == "__main__":
    main()
