"""Train the motion prior on the CMU mocap retargeted onto anny, holding out whole subjects.

The clips come from the canonical "motions" table of the retargeted CMU clips (``humancal.retarget``), the
table the ``mocap_clips`` asset materialises. It is read from ``--motions-table`` when that file exists
(the same default file as ``scripts/train_lifter.py``, so one retargeting serves both); otherwise every BVH
clip of the data root (``humancal.settings.dataset_dir("cmu_mocap")/bvh_daz``) is retargeted first (long:
minutes per subject) and the table is written there for the next run.

Prints one line per epoch (losses, held-out MPJPE), the training wall time and the held-out figures, and
writes the weights pair (``<out>.safetensors`` + ``<out>.json``, ``humancal.prior.save_prior``) outside the
repository. ``--ship`` also writes the weights humancal ships (``humancal/weights/motion_prior.*``); that is
how the shipped weights were made.

    python scripts/train_prior.py [--variant motion_prior] [--seed 0] [--workers 2] [--threads 1] [--out /tmp/humancal_prior/x]
                                  [--epochs N] [--steps-per-epoch N] [--learning-rate LR] [--weight-local-linear W]
                                  [--exclude-subjects 02,14 --held-out-subjects 06]   # settings chosen on a validation subject
    python scripts/train_prior.py --ship            # retrain the shipped weights
"""

from __future__ import annotations

import argparse
import logging
import os
import tempfile
import time
from pathlib import Path

import pandas as pd
import torch

from humancal.lifter import HELD_OUT_CMU_SUBJECTS
from humancal.prior import PRIOR_VARIANTS, SHIPPED_PRIOR_STEM, PriorConfig, save_prior, train_motion_prior
from humancal.settings import REPO_ROOT, dataset_dir

_DEFAULT_TABLE = Path(tempfile.gettempdir()) / "humancal_lifter" / "cmu_motions.parquet"
_DEFAULT_DIR = Path(tempfile.gettempdir()) / "humancal_prior"


def _retargeted_clips(table_path: Path, body_model) -> list:
    """Every retargeted CMU clip (``RetargetedClip``), retargeting first if the table is not there."""
    from humancal.retarget import clips_to_motions_table, motions_table_to_clips, retarget_clips

    if table_path.exists():
        print(f"reading retargeted CMU motions from {table_path}")
        return motions_table_to_clips(pd.read_parquet(table_path))
    paths = sorted((dataset_dir("cmu_mocap", required_for="training the motion prior") / "bvh_daz").glob("*/*.bvh*"))
    print(f"retargeting {len(paths)} CMU clips onto anny (cached afterwards in {table_path}) ...")
    start = time.perf_counter()
    clips = retarget_clips(
        paths, body_model, progress=lambda done, total, name: print(f"  [{done}/{total}] {name}", flush=True)
    )
    print(f"retargeted in {time.perf_counter() - start:.0f} s")
    table_path.parent.mkdir(parents=True, exist_ok=True)
    partial = table_path.with_suffix(".partial")
    clips_to_motions_table(clips).to_parquet(partial)
    os.replace(partial, table_path)
    return clips


def _print_epoch(record: dict) -> None:
    print(
        f"epoch {record['epoch']:3d}  loss {record['train_loss']:8.4f}  6D {record['train_pose6d']:.5f}  "
        f"train keypoints {record['train_keypoint_error_mm']:6.1f} mm  KL {record['train_kl']:6.3f}  "
        f"local-linear {record['train_local_linear']:.4f}  held-out MPJPE {record['val_mpjpe_mm']:6.1f} mm  "
        f"lr {record['lr']:.2e}  {record['elapsed_s']:6.0f} s",
        flush=True,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variant", default="motion_prior", choices=PRIOR_VARIANTS, help="PriorConfig.variant")
    parser.add_argument("--seed", type=int, default=0, help="PriorConfig.seed")
    parser.add_argument("--workers", type=int, default=2,
                        help="processes sharing each step's batch (data parallel; one per core is fastest)")
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads of each worker")
    parser.add_argument(
        "--out", type=Path, help="weights stem (outside the repo); default <tmp>/humancal_prior/<variant>"
    )
    parser.add_argument("--motions-table", type=Path, default=_DEFAULT_TABLE,
                        help="retargeted CMU motions table (read if present, else written)")
    parser.add_argument(
        "--held-out-subjects", default=",".join(HELD_OUT_CMU_SUBJECTS), help="held-out subjects, comma-separated"
    )
    parser.add_argument(
        "--exclude-subjects", default="",
        help="subjects left out of training and scoring altogether, comma-separated (choosing settings on a "
             "validation subject: exclude the test subjects 02,14 and hold out the validation one)",
    )
    parser.add_argument("--epochs", type=int, help="override PriorConfig.epochs")
    parser.add_argument("--steps-per-epoch", type=int, help="override PriorConfig.steps_per_epoch")
    parser.add_argument("--learning-rate", type=float, help="override PriorConfig.learning_rate (peak)")
    parser.add_argument("--weight-local-linear", type=float, help="override PriorConfig.weight_local_linear")
    parser.add_argument("--ship", action="store_true",
                        help="also write the shipped weights (humancal/weights/motion_prior.*); default variant only")
    args = parser.parse_args()
    tuned = (args.epochs, args.steps_per_epoch, args.learning_rate, args.weight_local_linear, args.exclude_subjects)
    other_split = args.held_out_subjects != ",".join(HELD_OUT_CMU_SUBJECTS)
    if args.ship and (args.variant != "motion_prior" or other_split or any(v not in (None, "") for v in tuned)):
        parser.error("--ship is for the default configuration of the motion_prior variant")
    out = (args.out or _DEFAULT_DIR / args.variant).resolve()
    if out.is_relative_to(REPO_ROOT):
        parser.error(f"--out {out} is inside the repository; trained weights are artifacts, keep them outside")
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    if args.workers < 1 or args.threads < 1:
        parser.error("--workers and --threads must be positive")
    torch.set_num_threads(args.threads)

    from humancal.body import BodyModel

    body_model = BodyModel()
    clips = _retargeted_clips(args.motions_table, body_model)
    excluded = {s for s in args.exclude_subjects.split(",") if s}
    if excluded:
        clips = [c for c in clips if c.subject not in excluded]
        print(f"left out altogether: subjects {sorted(excluded)}")
    held_out = tuple(args.held_out_subjects.split(","))
    overrides = {k: v for k, v in (("epochs", args.epochs), ("steps_per_epoch", args.steps_per_epoch),
                                   ("learning_rate", args.learning_rate),
                                   ("weight_local_linear", args.weight_local_linear)) if v is not None}
    config = PriorConfig.default(args.variant, args.seed).replace(**overrides)
    print(f"{len(clips)} clips, {sum(len(c.bone_rotmats_local) for c in clips)} frames; held out: {list(held_out)}")
    print(f"config {config.digest()}: variant {config.variant}, hidden {config.hidden_size}, latent "
          f"{config.latent_dim}, {config.epochs} epochs x {config.steps_per_epoch} steps x {config.batch_size} "
          f"windows of {config.clip_frames} frames, {args.workers} worker(s) of {args.threads} thread(s)")
    trained = train_motion_prior(clips, config, body_model, progress=_print_epoch, held_out_subjects=held_out,
                                 workers=args.workers, threads=args.threads)
    command = (f"python scripts/train_prior.py --variant {args.variant} --seed {args.seed} --workers {args.workers} "
               f"--threads {args.threads}")
    extra = f" --held-out-subjects {args.held_out_subjects}" if held_out != tuple(HELD_OUT_CMU_SUBJECTS) else ""
    extra += f" --exclude-subjects {','.join(sorted(excluded))}" if excluded else ""
    info = {"trained_with": command + _overrides_text(overrides) + extra, "threads": args.threads, "workers": args.workers}
    sidecar = save_prior(trained, out, info)
    if args.ship:
        save_prior(trained, SHIPPED_PRIOR_STEM, {**info, "trained_with": command + " --ship"})
        print(f"shipped weights written to {SHIPPED_PRIOR_STEM}.safetensors / .json")
    held = trained.held_out
    print(f"\nheld-out subjects {list(trained.held_out_subjects)}, {int(held['windows'])} windows of "
          f"{config.clip_frames} frames: reconstruction MPJPE {held['mpjpe_mm']:.1f} mm (23 keypoints, "
          f"posterior mean), KL {held['kl']:.3f}")
    print(f"training wall time {trained.train_seconds:.0f} s ({trained.train_seconds / 60:.1f} min), CPU time "
          f"{trained.train_cpu_seconds:.0f} s; weights "
          f"{out}.safetensors (digest {sidecar['digest'][:16]}, data {trained.data_digest[:16]})")


def _overrides_text(overrides: dict) -> str:
    return "".join(f" --{name.replace('_', '-')} {value}" for name, value in overrides.items())


if __name__ == "__main__":
    main()
