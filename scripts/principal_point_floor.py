"""What the self-calibration convention costs on Shelf by itself (ground truth only: a diagnostic).

Every self-calibrated camera of humancal, like the paper's, has its principal point at the image centre; humancal's
has one focal length (square pixels), the paper's fx and fy. Shelf's calibrated cameras do not: principal points up
to about 50 px off centre, and fx and fy up to 1.6 % apart. Two tables, both from exact, noise-free projections
of the ground-truth joints:

1. each true camera's pose alone re-estimated with its principal point moved to the centre
   (:func:`evaluation.camera_metrics.centred_principal_point_floor`; no alignment);
2. the whole rig self-calibrated under a convention (:func:`evaluation.calibration_floor.self_calibration_floor`:
   every pose, focal length and point free, least squares from the truth), scored by the benchmark's protocol
   (similarity alignment of the centres): humancal's convention, the paper's, humancal's with a free k1, and
   humancal's with the true principal points.
   The first row is the floor under the ``init`` and ``int_ext`` rows of the Shelf tables: a calibration from the
   real detections cannot be expected below it.

    python scripts/principal_point_floor.py [--max-points 2000]
"""

from __future__ import annotations

import argparse

import numpy as np
import pandas as pd

from evaluation.calibration_floor import self_calibration_floor
from evaluation.camera_metrics import centred_principal_point_floor
from humancal.datasets.shelf import load_shelf
from humancal.settings import dataset_dir

CONVENTIONS = {
    "centred principal point, one focal (humancal)": {"centred_principal_point": True, "square_pixels": True},
    "centred principal point, fx and fy (the paper)": {"centred_principal_point": True, "square_pixels": False},
    "centred principal point, one focal, k1 (humancal's lens option)": {"centred_principal_point": True,
                                                                        "square_pixels": True, "free_k1": True},
    "true principal point, one focal": {"centred_principal_point": False, "square_pixels": True},
}
METRICS = ("focal_error_pct", "position_error_mm", "angle_error_deg", "residual_px")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-points", type=int, default=2000, help="ground-truth joints used by the rig fit")
    args = parser.parse_args()
    shelf = load_shelf(dataset_dir("shelf_4dassoc", required_for="the principal-point floor"))
    joints = shelf.gt_joints_world_m[shelf.gt_present].reshape(-1, 3)
    joints = joints[np.isfinite(joints).all(axis=1)]

    print("1. Each camera's pose alone, principal point centred (no alignment)\n")
    table = pd.DataFrame(centred_principal_point_floor(shelf.cameras, joints))
    table.index.name = "view"
    table.loc["mean"] = table.mean()
    print(table.to_markdown(floatfmt=".2f"))

    print(f"\n2. The whole rig self-calibrated under a convention ({min(len(joints), args.max_points)} joints; "
          "similarity alignment of the centres)\n")
    rows, per_view = {}, None
    for name, convention in CONVENTIONS.items():
        floor = self_calibration_floor(shelf.cameras, joints, max_points=args.max_points, **convention)
        rows[name] = {metric: float(np.mean(floor[metric])) for metric in METRICS}
        if per_view is None:
            per_view = pd.DataFrame({metric: floor[metric] for metric in METRICS})
    print(pd.DataFrame(rows).T.rename_axis("convention (mean over views)").to_markdown(floatfmt=".2f"))
    per_view.index.name = "view"
    print(f"\nPer view, {next(iter(CONVENTIONS))}:\n")
    print(per_view.to_markdown(floatfmt=".2f"))


if __name__ == "__main__":
    main()
