"""Micro-benchmark of the motion prior's decoder, the call the fitting stage makes hundreds of times.

Workload: decode latents of P people x F frames (default 4 x 900), map the 6D output to rotation matrices,
then backward from a scalar (gradients w.r.t. the latents); and the same followed by the body model's fast
keypoint path (what one fitting step costs). Reports the median wall time and the process CPU time of
``--repeats`` runs after one warm-up, per variant.

``--windows``: decode as the body fit does, in the latent windows of ``humancal.prior.windows.window_layout``
(``BodyFitConfig.window_frames`` / ``window_overlap``), all windows of all people in one batch; and time a candidate
non-recurrent decoder next to the variants: dilated 1D convolutions over time (``--conv-width`` channels, kernel
3, dilations 1, 2, 4, 8: a receptive field of 31 frames, about the window), with residual connections, the
skip connection and the same output head. It is untrained: only its time means something.

    python scripts/bench_prior.py [--people 4] [--frames 900] [--repeats 5] [--threads 2] [--weights PATH] \
        [--windows [--conv-width 128]]
"""

from __future__ import annotations

import argparse
import statistics
import time

import torch
from torch import nn

from humancal.body import BodyModel
from humancal.prior import MotionVAE, PriorConfig, load_prior, pose6d_to_rotmats, with_root
from humancal.prior.model import POSE6D_DIM, identity_pose6d
from humancal.prior.windows import window_layout


class ConvDecoder(nn.Module):
    """The timing candidate of ``--windows``: ``decode(z)`` (B, T, latent) -> (B, T, 21, 6) by dilated 1D convolutions
    over time, residual, then the prior's skip connection and output head (``MotionVAE``'s sizes)."""

    def __init__(self, latent_dim: int, width: int, head_width: int, dilations=(1, 2, 4, 8)) -> None:
        super().__init__()
        self.latent_dim = latent_dim
        self.inp = nn.Conv1d(latent_dim, width, 1)
        self.layers = nn.ModuleList(nn.Conv1d(width, width, 3, dilation=d, padding=d) for d in dilations)
        self.head = nn.Sequential(nn.Linear(width + latent_dim, head_width), nn.GELU(),
                                  nn.Linear(head_width, POSE6D_DIM))
        self.register_buffer("identity", identity_pose6d().reshape(POSE6D_DIM))

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        x = self.inp(z.transpose(1, 2))
        for layer in self.layers:
            x = x + nn.functional.gelu(layer(x))
        out = self.head(torch.cat([x.transpose(1, 2), z], dim=-1)) + self.identity
        return out.view(*z.shape[:2], -1, 6)


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
    parser.add_argument("--windows", action="store_true", help="decode in the body fit's latent windows, and time "
                        "the convolution candidate")
    parser.add_argument("--conv-width", type=int, default=128, help="channels of the convolution candidate")
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
    layout = None
    if args.windows:
        from humancal.fitting.config import BodyFitConfig

        fit = BodyFitConfig()
        layout = window_layout(F, fit.window_frames, fit.window_overlap)
        config = next(iter(models.values())).config
        models["temporal_conv"] = ConvDecoder(config.latent_dim, args.conv_width, config.head_width).eval()
    shape = (P, F) if layout is None else (P * len(layout.starts), layout.length)
    print(f"{P} people x {F} frames, {args.threads} threads, median of {args.repeats}"
          + ("" if layout is None else f"; decoded as {shape[0]} windows of {shape[1]} frames"))
    for variant, model in models.items():
        model.requires_grad_(False)
        z = torch.randn(*shape, model.latent_dim, requires_grad=True)
        root = torch.eye(3).expand(*shape, 3, 3)
        translation = torch.zeros(*shape, 3)
        rest_b = rest if layout is None else body.rest_skeleton(torch.full((shape[0], 6), 0.5))

        def decode_only():
            z.grad = None
            rotmats = pose6d_to_rotmats(model.decode(z))
            rotmats.square().sum().backward()

        def decode_and_keypoints():
            z.grad = None
            rotmats = with_root(pose6d_to_rotmats(model.decode(z)), root)
            body.keypoints(rest_b, rotmats, translation).square().sum().backward()

        for name, fn in (("decode fwd+bwd", decode_only), ("decode + keypoints fwd+bwd", decode_and_keypoints)):
            wall, cpu = _time(fn, args.repeats)
            print(f"{variant:14s} {name:28s} wall {1000 * wall:7.1f} ms   CPU {1000 * cpu:7.1f} ms")


if __name__ == "__main__":
    main()
