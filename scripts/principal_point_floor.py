"""What holding the principal point at the image centre costs on Shelf by itself (ground truth only: a diagnostic).

Every self-calibrated camera of humancal, like the paper's, has its principal point at the image centre. Shelf's
calibrated cameras do not (offsets up to about 50 px). This script re-estimates each true camera's pose with its
principal point moved to the centre, from the exact projections of the ground-truth joints
(:func:`evaluation.camera_metrics.centred_principal_point_floor`), and prints the angle and position errors that are
left: a floor for any self-calibration with that convention. The residual column shows how little of the offset the
images reveal (pixels, against detections several pixels off).

    python scripts/principal_point_floor.py
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from evaluation.camera_metrics import centred_principal_point_floor
from humancal.datasets.shelf import load_shelf
from humancal.settings import dataset_dir


def main() -> None:
    shelf = load_shelf(dataset_dir("shelf_4dassoc", required_for="the principal-point floor"))
    joints = shelf.gt_joints_world_m[shelf.gt_present].reshape(-1, 3)
    floor = centred_principal_point_floor(shelf.cameras, joints[np.isfinite(joints).all(axis=1)])
    table = pd.DataFrame(floor)
    table.index.name = "view"
    table.loc["mean"] = table.mean()
    print(table.to_markdown(floatfmt=".2f"))


if __name__ == "__main__":
    main()
