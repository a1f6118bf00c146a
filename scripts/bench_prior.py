"""Micro-benchmark of the motion prior's decoder, the call the fitting stage makes hundreds of times.

Workload: decode latents of P people x F frames (default 4 x 900), map the 6D output to rotation matrices,
then backward from a scalar (gradients w.r.t. the latents); and the same followed by the body model's fast
keypoint path (what one fitting step costs). Reports the median wall time and the process CPU time of
``--repeats`` runs after one warm-up, per variant.

    python scripts/bench_prior.py [--people 4] [--frames 900] [--repeats 5] [--threads 2] [--weights PATH]
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch

from humancal.body import BodyModel
from humancal.prior import MotionVAE, PriorConfig, load_prior, pose6d_to_rotmats, with_root


def _time(fn, repeats: int) -> tuple[float, float]:
    fn()  # warm-up
    walls, cpus = [], []
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return statistics.median(walls), statistics.median(cpus)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--people", type=int, default=4)
    parser.add_argument("--frames", type=int, default=900)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--weights", help="a trained prior (default: untrained networks of each variant's default size)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    body = BodyModel()
    rest = body.rest_skeleton(torch.full((args.people, 6), 0.5))
    if args.weights:
        model, _ = load_prior(args.weights)
        models = {model.config.variant: model}
    else:
        models = {v: MotionVAE(PriorConfig.default(v)).eval() for v in ("motion_prior", "per_frame")}
    P, F = args.people, args.frames
    print(f"{P} people x {F} frames, {args.threads} threads, median of {args.repeats}")
    for variant, model in models.items():
        model.requires_grad_(False)
        z = torch.randn(P, F, model.latent_dim, requires_grad=True)
        root = torch.eye(3).expand(P, F, 3, 3)
        translation = torch.zeros(P, F, 3)

        def decode_only():
            z.grad = None
            rotmats = pose6d_to_rotmats(model.decode(z))
            rotmats.square().sum().backward()

        def decode_and_keypoints():
            z.grad = None
            rotmats = with_root(pose6d_to_rotmats(model.decode(z)), root)
            body.keypoints(rest, rotmats, translation).square().sum().backward()

        for name, fn in (("decode fwd+bwd", decode_only), ("decode + keypoints fwd+bwd", decode_and_keypoints)):
            wall, cpu = _time(fn, args.repeats)
            print(f"{variant:14s} {name:28s} wall {1000 * wall:7.1f} ms   CPU {1000 * cpu:7.1f} ms")


if __name__ == "__main__":
    main()
