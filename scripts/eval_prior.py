"""Evaluate trained motion priors on the held-out CMU subjects: reconstruction and the denoising benchmark.

For every ``--weights VARIANT=PATH`` (a weights pair written by ``scripts/train_prior.py``; default: the shipped
default prior) prints the held-out reconstruction MPJPE (mm) and acceleration error (mm/s^2), then the
denoising / completion benchmark (``humancal.prior.evaluate``: 30 mm noise and 20 % missing in 3D, and the same
seen by four virtual cameras with 5 px noise) for the no-prior fit and each prior, one row per method and
setting. ``--tune`` instead fits segments of the TRAINING subjects with a small grid of fit weights and prints
which ones fit best (that is how ``DENOISE_FIT_CONFIGS`` was chosen; the held-out clips are never used for it).

The clips come from the canonical motions table (``--motions-table``, the file ``scripts/train_lifter.py`` and
``scripts/train_prior.py`` write).

    python scripts/eval_prior.py [--weights motion_prior=PATH ...] [--segments 16] [--frames 120] [--threads 2]
    python scripts/eval_prior.py --tune [--weights ...]
    python scripts/eval_prior.py --subjects 06 --weights motion_prior=PATH   # a validation subject instead
"""

from __future__ import annotations

import argparse
import itertools
import logging
import tempfile
import time
from pathlib import Path

import pandas as pd
import torch

from humancal.body import BodyModel
from humancal.lifter import HELD_OUT_CMU_SUBJECTS
from humancal.prior import load_prior
from humancal.prior.evaluate import (
    DENOISE_FIT_CONFIGS,
    RECONSTRUCTION_WINDOW,
    denoise_method,
    denoising_benchmark,
    motion_segments,
    reconstruction_method,
    reconstruction_report,
)
from humancal.prior.weights import SHIPPED_PRIOR_STEM
from humancal.retarget import motions_table_to_clips

_DEFAULT_TABLE = Path(tempfile.gettempdir()) / "humancal_lifter" / "cmu_motions.parquet"


def _weights(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items or [f"motion_prior={SHIPPED_PRIOR_STEM}"]:
        variant, _, path = item.partition("=")
        if not path:
            raise SystemExit(f"--weights takes VARIANT=PATH, got {item!r}")
        out[variant] = path
    return out


_TUNE_LATENT = (1e-3,)
"""Latent weights of the ``--tune`` grid (1e-4 and 1e-2 changed MPJPE by under 0.05 mm: docs/motion_prior.md)."""
_TUNE_LOCAL_LINEAR = (30.0, 100.0, 300.0, 1000.0)
"""Local-linear weights of the ``--tune`` grid (1 to 3000 were tried with the 20-epoch priors; 1000 was already
too strong and 30 too weak)."""


def _tune(body, clips, priors, args) -> None:
    train = [c for c in clips if c.subject not in HELD_OUT_CMU_SUBJECTS and c.subject not in args.subjects]
    segments = motion_segments(train, args.frames, args.segments, seed=args.seed + 1)
    rows = []
    for setting in args.settings:
        base = DENOISE_FIT_CONFIGS["denoise_no_prior"].replace(iterations=args.iterations or 300)
        for weight_rest in (1e-4, 1e-2):
            config = base.replace(weight_rest=weight_rest)
            r = denoising_benchmark(body, segments, {}, {"denoise_no_prior": config}, setting, args.seed)
            rows.append({**r.iloc[0].to_dict(), "weight_rest": weight_rest})
            print(rows[-1], flush=True)
        for variant, prior in priors.items():
            method = denoise_method(variant)
            base = DENOISE_FIT_CONFIGS[method].replace(iterations=args.iterations or 300)
            for latent, local_linear in itertools.product(_TUNE_LATENT, _TUNE_LOCAL_LINEAR):
                config = base.replace(weight_latent=latent, weight_local_linear=local_linear)
                r = denoising_benchmark(body, segments, {variant: prior}, {method: config}, setting, args.seed,
                                        include_no_prior=False)
                rows.append({**r.iloc[0].to_dict(), "weight_latent": latent, "weight_local_linear": local_linear})
                print(rows[-1], flush=True)
    table = pd.DataFrame(rows)
    print(table.to_string(float_format=lambda v: f"{v:.4g}"))
    best = table.loc[table.groupby(["method", "setting"])["mpjpe_mm"].idxmin()]
    print("\nlowest MPJPE per method and setting (training subjects):")
    print(best.to_string(float_format=lambda v: f"{v:.4g}"))
    priors_only = table.dropna(subset=["weight_local_linear"])
    summed = priors_only.groupby(["method", "weight_latent", "weight_local_linear"])["mpjpe_mm"].sum()
    print("\nthe rule of DENOISE_FIT_CONFIGS, lowest MPJPE summed over the settings, per method:")
    print(summed.loc[summed.groupby(level="method").idxmin()].to_string(float_format=lambda v: f"{v:.4g}"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--weights", action="append", help="VARIANT=PATH of a trained prior (repeatable)")
    parser.add_argument("--motions-table", type=Path, default=_DEFAULT_TABLE)
    parser.add_argument("--segments", type=int, default=16)
    parser.add_argument("--frames", type=int, default=120)
    parser.add_argument("--iterations", type=int, help="Adam steps of every fit (default: DENOISE_FIT_CONFIGS)")
    parser.add_argument("--settings", default="3d,2d", help="comma-separated: 3d, 2d")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument(
        "--subjects", default=",".join(HELD_OUT_CMU_SUBJECTS),
        help="subjects evaluated, comma-separated (default the held-out test subjects; a validation subject when "
             "choosing training settings: scripts/train_prior.py --exclude-subjects)",
    )
    parser.add_argument("--tune", action="store_true", help="grid of fit weights on training-subject segments")
    parser.add_argument("--no-denoise", action="store_true", help="reconstruction only")
    args = parser.parse_args()
    args.settings = [s for s in args.settings.split(",") if s]
    args.subjects = tuple(s for s in args.subjects.split(",") if s)
    logging.basicConfig(level=logging.WARNING)
    torch.set_num_threads(args.threads)

    clips = motions_table_to_clips(pd.read_parquet(args.motions_table))
    body = BodyModel()
    priors = {}
    for variant, path in _weights(args.weights).items():
        priors[variant], info = load_prior(path, variant)
        print(f"{variant}: {path} (trained in {float(info['train_seconds']):.0f} s)")
    if args.tune:
        _tune(body, clips, priors, args)
        return
    held = [c for c in clips if c.subject in args.subjects]
    if not held:
        raise SystemExit(f"--subjects {','.join(args.subjects)}: no clip of these subjects in {args.motions_table}")
    print(f"evaluated subjects {', '.join(args.subjects)}: {len(held)} clips, "
          f"{sum(len(c.root_translation_m) for c in held)} frames")
    recon = []
    for variant, prior in priors.items():
        start = time.perf_counter()
        report = reconstruction_report(prior, held, body)
        whole = reconstruction_report(prior, held, body, window=None)
        recon.append({"method": reconstruction_method(variant), **report, "mpjpe_whole_clip_mm": whole["mpjpe_mm"],
                      "accel_whole_clip_mm_s2": whole["accel_error_mm_s2"], "seconds": time.perf_counter() - start})
    frames, overlap = RECONSTRUCTION_WINDOW
    print(f"\nreconstruction (posterior means, root at identity; clips cut into the body fit's windows of {frames} "
          f"frames, overlap {overlap}, and whole):")
    print(pd.DataFrame(recon).to_string(index=False, float_format=lambda v: f"{v:.1f}"))
    if args.no_denoise:
        return
    segments = motion_segments(held, args.frames, args.segments, args.seed)
    configs = {m: c if args.iterations is None else c.replace(iterations=args.iterations)
               for m, c in DENOISE_FIT_CONFIGS.items()}
    tables = [denoising_benchmark(body, segments, priors, configs, setting, args.seed) for setting in args.settings]
    table = pd.concat(tables, ignore_index=True)
    print(f"\ndenoising and completion: {len(segments)} held-out segments of {args.frames} frames")
    print(table.drop(columns=["variant"]).to_string(index=False, float_format=lambda v: f"{v:.1f}"))


if __name__ == "__main__":
    main()
