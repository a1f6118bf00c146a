"""Train the 2D-to-3D lifter on the CMU mocap retargeted onto anny, holding out whole subjects.

The motion comes from the canonical "motions" table of the retargeted CMU clips (``humancal.retarget``). The
table is read from ``--motions-table`` when that file exists; otherwise every BVH clip of the data root
(``humancal.settings.dataset_dir("cmu_mocap")/bvh_daz``) is retargeted first (long: minutes per subject) and
the table is written there for the next run. ``--synthetic`` trains on procedural motions of
``humancal.synthetic`` instead (no external data; for development).

Prints the per-epoch losses, the held-out MPJPE / PA-MPJPE (mm; overall and by how much of the body the
detection shows), the training wall time and the checkpoint size, and saves the checkpoint (a plain dict,
``torch.load(..., weights_only=True)``) to ``--out``, never inside the repository. ``--ship`` also writes the
weights humancal ships (``humancal/weights/lifter.safetensors`` and its ``.json`` sidecar with the training
configuration, digest and held-out figures); that is how the shipped weights were made.

    python scripts/train_lifter.py [--out /tmp/humancal_lifter/lifter.pt] [--val-subjects 02,14] [--threads 1]
    python scripts/train_lifter.py --ship            # retrain the shipped weights (about 15 minutes on 2 cores)
"""

from __future__ import annotations

import argparse
import logging
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import torch

from humancal.lifter import (
    HELD_OUT_CMU_SUBJECTS,
    SHIPPED_LIFTER_STEM,
    LifterConfig,
    held_out_report,
    load_lifter,
    train_lifter,
    write_lifter_weights,
)
from humancal.lifter.evaluate import HELD_OUT_EVAL_SAMPLES
from humancal.settings import REPO_ROOT, dataset_dir

_DEFAULT_DIR = Path(tempfile.gettempdir()) / "humancal_lifter"


def _cmu_clips(table_path: Path) -> list[tuple[str, str, np.ndarray]]:
    """(name, subject, keypoints_world_m) of every retargeted CMU clip, retargeting first if needed."""
    from humancal.retarget import clips_to_motions_table, motions_table_to_clips, retarget_clips

    if table_path.exists():
        print(f"reading retargeted CMU motions from {table_path}")
        clips = motions_table_to_clips(pd.read_parquet(table_path))
    else:
        from humancal.body import BodyModel

        paths = sorted((dataset_dir("cmu_mocap", required_for="training the lifter") / "bvh_daz").glob("*/*.bvh*"))
        print(f"retargeting {len(paths)} CMU clips onto anny (cached afterwards in {table_path}) ...")
        start = time.perf_counter()
        clips = retarget_clips(
            paths, BodyModel(), progress=lambda done, total, name: print(f"  [{done}/{total}] {name}", flush=True)
        )
        print(f"retargeted in {time.perf_counter() - start:.0f} s")
        table_path.parent.mkdir(parents=True, exist_ok=True)
        partial = table_path.with_suffix(".partial")
        clips_to_motions_table(clips).to_parquet(partial)
        os.replace(partial, table_path)
    return [(clip.name, clip.subject, np.asarray(clip.keypoints_world_m)) for clip in clips]


def _synthetic_clips(people: int, frames: int, seed: int) -> list[tuple[str, str, np.ndarray]]:
    from humancal.body import BodyModel
    from humancal.synthetic import generate_motions, sample_people

    body, rng = BodyModel(), np.random.default_rng(seed)
    found = sample_people(body, people, rng, height_range_m=(1.45, 1.98))
    clips = []
    for first in range(0, people, 4):
        rest = body.rest_skeleton(torch.as_tensor(found.phenotypes[first : first + 4], dtype=body.dtype))
        with torch.no_grad():
            motions = generate_motions(body, rest, frames, 30.0, (6.0, 6.0), rng)
        for p in range(rest.num_people):
            clips.append((f"synthetic_{first + p:02d}", f"s{first + p:02d}", motions.keypoints_world_m[p]))
    return clips


def _print_epoch(record: dict) -> None:
    if record["kind"] == "epoch":
        print(
            f"epoch {record['epoch']:3d}  train loss {record['train_loss_m'] * 1000:7.1f} mm  "
            f"val loss {record['val_loss_m'] * 1000:7.1f} mm  val PA-MPJPE {record['val_pa_mpjpe_mm']:6.1f} mm  "
            f"height MAE {record['val_height_mae_mm']:6.1f} mm  lr {record['lr']:.2e}  {record['elapsed_s']:6.0f} s",
            flush=True,
        )


def _held_out_report(checkpoint: dict, val_clips: list[tuple[str, np.ndarray]]) -> pd.DataFrame:
    """Fresh held-out samples (another seed than validation), through the whole inference path."""
    table = held_out_report(load_lifter(checkpoint), val_clips).drop(columns="num_samples")
    print(f"\nheld-out subjects, {HELD_OUT_EVAL_SAMPLES} fresh samples (root-relative, mm):")
    print(table.to_string(float_format=lambda v: f"{v:.1f}"))
    return table


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", type=Path, default=_DEFAULT_DIR / "lifter.pt", help="checkpoint path (outside the repo)"
    )
    parser.add_argument("--motions-table", type=Path, default=_DEFAULT_DIR / "cmu_motions.parquet",
                        help="retargeted CMU motions table (read if present, else written)")
    parser.add_argument(
        "--val-subjects", default=",".join(HELD_OUT_CMU_SUBJECTS), help="held-out subjects, comma-separated"
    )
    parser.add_argument("--synthetic", action="store_true", help="train on procedural synthetic motions instead of CMU")
    parser.add_argument("--threads", type=int, default=1,
                        help="torch CPU threads (on a shared 2-core machine 2 threads measured several times slower)")
    parser.add_argument("--epochs", type=int, help="override LifterConfig.epochs")
    parser.add_argument("--samples-per-epoch", type=int, help="override LifterConfig.samples_per_epoch")
    parser.add_argument("--seed", type=int, default=0, help="LifterConfig.seed")
    parser.add_argument("--ship", action="store_true",
                        help="also write the weights shipped with humancal (humancal/weights/lifter.safetensors + "
                             ".json, with the held-out figures); only for the default configuration on the CMU mocap")
    parser.add_argument("--from-checkpoint", type=Path,
                        help="skip training: report (and with --ship, ship) this checkpoint written by an earlier run")
    args = parser.parse_args()
    if args.ship and (args.synthetic or args.epochs or args.samples_per_epoch):
        parser.error("--ship is for the default configuration trained on the CMU mocap")
    out = args.out.resolve()
    if out.is_relative_to(REPO_ROOT):
        parser.error(f"--out {out} is inside the repository; checkpoints are artifacts, keep them outside")
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    torch.set_num_threads(args.threads)

    if args.synthetic:
        clips = _synthetic_clips(24, 900, seed=args.seed)
        val_subjects = {"s20", "s21", "s22", "s23"}
    else:
        clips = _cmu_clips(args.motions_table)
        val_subjects = set(args.val_subjects.split(","))
    train = [(subject, kp) for _, subject, kp in clips if subject not in val_subjects]
    val = [(subject, kp) for _, subject, kp in clips if subject in val_subjects]
    if not train or not val:
        parser.error(f"--val-subjects {sorted(val_subjects)} leave no training or no validation clips")
    frames = lambda part: sum(len(kp) for _, kp in part)  # noqa: E731
    print(f"train: {len(train)} clips, {frames(train)} frames, subjects {sorted({s for s, _ in train})}")
    print(f"held out: {len(val)} clips, {frames(val)} frames, subjects {sorted(val_subjects)}")

    overrides = {k: v for k, v in (("epochs", args.epochs), ("samples_per_epoch", args.samples_per_epoch)) if v}
    config = LifterConfig.default().replace(seed=args.seed, **overrides)
    print(f"config: width {config.width}, {config.num_blocks} blocks, {config.epochs} epochs x "
          f"{config.samples_per_epoch} samples, batch {config.batch_size}, {args.threads} thread(s)")
    if args.from_checkpoint:
        checkpoint = torch.load(args.from_checkpoint, map_location="cpu", weights_only=True)
        if checkpoint["config"] != config.to_dict():
            parser.error(f"{args.from_checkpoint} was trained with another configuration than the one asked for")
        train_s = float(checkpoint["training_time_s"])
        out = args.from_checkpoint.resolve()
    else:
        start = time.perf_counter()
        checkpoint, _ = train_lifter(train, val, config, progress=_print_epoch)
        train_s = time.perf_counter() - start
        out.parent.mkdir(parents=True, exist_ok=True)
        partial = out.with_suffix(".partial")
        torch.save(checkpoint, partial)
        os.replace(partial, out)
    report = _held_out_report(checkpoint, val)
    if args.ship:
        info = {
            "trained_with": f"python scripts/train_lifter.py --seed {args.seed} --threads {args.threads} "
                            "(LifterConfig.default(), CMU mocap retargeted onto anny)",
            "torch_version": torch.__version__,
            "held_out": {group: {k: round(float(v), 2) for k, v in row.items()}
                         for group, row in report.to_dict(orient="index").items()},
            "held_out_samples": HELD_OUT_EVAL_SAMPLES,
        }
        sidecar = write_lifter_weights(checkpoint, SHIPPED_LIFTER_STEM, info)
        print(f"shipped weights written to {SHIPPED_LIFTER_STEM}.safetensors / .json (digest {sidecar['digest'][:16]})")
    final = checkpoint["val_metrics"]
    print(f"\nvalidation ({config.validation_samples} samples): MPJPE {final['mpjpe_mm']:.1f} mm, "
          f"PA-MPJPE {final['pa_mpjpe_mm']:.1f} mm")
    size_mb = out.stat().st_size / 1e6
    print(f"training wall time {train_s:.0f} s ({train_s / 60:.1f} min); checkpoint {size_mb:.2f} MB -> {out}")


if __name__ == "__main__":
    main()
