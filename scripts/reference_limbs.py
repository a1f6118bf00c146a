"""The reference adult's limbs of ``humancal.calibration.world_scale.REFERENCE_LIMB_SUM_M``, measured on the CMU
subjects the shipped lifter learned from: per subject, the sum over the eight limbs of each limb's median length
over all its frames (the canonical keypoints of its mocap retargeted onto anny), then the median over subjects.

    python scripts/reference_limbs.py [--motions-table /tmp/humancal_lifter/cmu_motions.parquet]

The motions table is the one ``scripts/train_lifter.py`` writes (it retargets the data root's CMU mocap when the
file is missing: minutes per subject).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from humancal.calibration.world_scale import REFERENCE_LIMB_SUM_M, SCALE_LIMBS
from humancal.lifter import HELD_OUT_CMU_SUBJECTS
from humancal.lifter.data import clip_heights_m
from humancal.retarget import motions_table_to_clips


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--motions-table", type=Path,
                        default=Path(tempfile.gettempdir()) / "humancal_lifter" / "cmu_motions.parquet")
    args = parser.parse_args()
    if not args.motions_table.exists():
        raise SystemExit(f"{args.motions_table} does not exist: run scripts/train_lifter.py first (it writes it)")
    clips = motions_table_to_clips(pd.read_parquet(args.motions_table))
    a, b = np.array(SCALE_LIMBS).T
    rows = []
    for subject in sorted({c.subject for c in clips} - set(HELD_OUT_CMU_SUBJECTS)):
        keypoints = np.concatenate([np.asarray(c.keypoints_world_m) for c in clips if c.subject == subject])
        limbs = float(np.median(np.linalg.norm(keypoints[:, a] - keypoints[:, b], axis=-1), axis=0).sum())
        height = float(np.median(clip_heights_m([(subject, keypoints)])))
        rows.append((subject, limbs, height))
        print(f"subject {subject}: limbs {limbs:.3f} m, standing height {height:.3f} m")
    limbs = float(np.median([r[1] for r in rows]))
    print(f"median over {len(rows)} training subjects: limbs {limbs:.3f} m (REFERENCE_LIMB_SUM_M = "
          f"{REFERENCE_LIMB_SUM_M}), height {np.median([r[2] for r in rows]):.3f} m")


if __name__ == "__main__":
    main()
