"""Micro-benchmark of the body model: exact fast keypoint path vs anny's full forward + COCO regressor.

Workload: forward + backward of the 23 keypoints of P people x F frames (default 4 x 900 = 3,600 person-frames),
random phenotypes and poses, loss = mean squared keypoint, gradients w.r.t. phenotypes, rotations (as rotation
vectors) and root translations. The full forward runs one person and ``--chunk`` frames at a time (memory).
Each path runs in its own subprocess so that its peak resident memory is its own. "CPU s" is the process's CPU
time (all threads): on a shared machine it is steadier than the wall time.

    python scripts/bench_body.py [--people 4] [--frames 900] [--chunk 300] [--repeats 5] [--threads 2]
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time


def _workload(model, people: int, frames: int, seed: int):
    import torch

    generator = torch.Generator().manual_seed(seed)
    phenotypes = torch.rand(people, 6, generator=generator, dtype=model.dtype)
    rotvecs = 0.4 * torch.randn(people, frames, model.num_posed_bones, 3, generator=generator, dtype=model.dtype)
    translations = torch.randn(people, frames, 3, generator=generator, dtype=model.dtype)
    return phenotypes, rotvecs, translations


def _run_path(path: str, people: int, frames: int, chunk: int, repeats: int, threads: int) -> dict:
    import roma
    import torch

    from humancal.body import BodyModel

    torch.set_num_threads(threads)
    model = BodyModel()
    model_rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    phenotypes, rotvecs, translations = _workload(model, people, frames, seed=0)

    def once(phenotypes, rotvecs, translations) -> tuple[float, float, torch.Tensor, list[torch.Tensor]]:
        people, frames = rotvecs.shape[:2]
        leaves = [t.detach().clone().requires_grad_() for t in (phenotypes, rotvecs, translations)]
        start, start_cpu = time.perf_counter(), time.process_time()
        if path == "fast":
            rest = model.rest_skeleton(leaves[0])
            keypoints = model.keypoints(rest, roma.rotvec_to_rotmat(leaves[1]), leaves[2])
            (keypoints**2).mean().backward()
            result = keypoints.detach()
        else:
            parts = []
            scale = 1.0 / (people * frames * 23 * 3)
            for p in range(people):
                row = []
                for f0 in range(0, frames, chunk):
                    f1 = min(frames, f0 + chunk)
                    out = model.reference_forward(
                        leaves[0][p : p + 1],
                        roma.rotvec_to_rotmat(leaves[1][p : p + 1, f0:f1]),
                        leaves[2][p : p + 1, f0:f1],
                    )["keypoints"]
                    (scale * (out**2).sum()).backward()
                    row.append(out.detach())
                parts.append(torch.cat(row, dim=1))
            result = torch.cat(parts, dim=0)
        seconds, cpu_seconds = time.perf_counter() - start, time.process_time() - start_cpu
        return seconds, cpu_seconds, result, [leaf.grad for leaf in leaves]

    # Warm-up on a small slice (warp kernel load, allocator), then the timed runs.
    once(phenotypes[:1], rotvecs[:1, :16], translations[:1, :16])
    timings, cpu_timings, result, grads = [], [], None, None
    for _ in range(repeats):
        seconds, cpu_seconds, result, grads = once(phenotypes, rotvecs, translations)
        timings.append(seconds)
        cpu_timings.append(cpu_seconds)
    timings.sort()
    cpu_timings.sort()
    return {
        "path": path,
        "seconds_median": timings[len(timings) // 2],
        "seconds_min": timings[0],
        "cpu_seconds_median": cpu_timings[len(cpu_timings) // 2],
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "model_rss_mb": model_rss_mb,
        "keypoints": result.flatten().tolist(),
        "grads": [g.flatten().tolist() for g in grads],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--people", type=int, default=4)
    parser.add_argument("--frames", type=int, default=900)
    parser.add_argument("--chunk", type=int, default=300, help="frames per full-forward call")
    parser.add_argument("--repeats", type=int, default=5, help="timed runs of the fast path")
    parser.add_argument("--reference-repeats", type=int, default=1, help="timed runs of the full forward")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--path", choices=["fast", "reference"], help=argparse.SUPPRESS)
    args = parser.parse_args()

    if args.path:  # child process: one path, JSON on stdout
        print(json.dumps(_run_path(args.path, args.people, args.frames, args.chunk, args.repeats, args.threads)))
        return

    results = {}
    for path in ("fast", "reference"):
        repeats = args.repeats if path == "fast" else args.reference_repeats
        command = [sys.executable, __file__, "--path", path, "--people", str(args.people), "--frames",
                   str(args.frames), "--chunk", str(args.chunk), "--repeats", str(repeats), "--threads",
                   str(args.threads)]
        completed = subprocess.run(command, check=True, capture_output=True, text=True)
        results[path] = json.loads(completed.stdout.strip().splitlines()[-1])

    import torch

    fast, ref = results["fast"], results["reference"]
    keypoint_diff = (torch.tensor(fast["keypoints"]) - torch.tensor(ref["keypoints"])).abs().max().item()
    grad_diffs = [
        ((torch.tensor(a) - torch.tensor(b)).abs().max() / torch.tensor(b).abs().max().clamp_min(1e-12)).item()
        for a, b in zip(fast["grads"], ref["grads"])
    ]
    person_frames = args.people * args.frames
    print(f"keypoints forward+backward, {args.people} people x {args.frames} frames = {person_frames} person-frames, "
          f"{args.threads} threads, float32")
    print(f"{'path':<36} {'median s':>9} {'min s':>8} {'CPU s':>7} {'us/person-frame':>16} {'peak RSS MB':>12} "
          f"{'(model alone)':>14}")
    labels = {
        "fast": "fast (rest skeleton + 22-bone FK)",
        "reference": f"anny full forward + COCO ({args.chunk}/call)",
    }
    for path in ("fast", "reference"):
        r = results[path]
        print(f"{labels[path]:<36} {r['seconds_median']:>9.3f} {r['seconds_min']:>8.3f} "
              f"{r['cpu_seconds_median']:>7.2f} {1e6 * r['seconds_median'] / person_frames:>16.1f} "
              f"{r['peak_rss_mb']:>12.0f} {r['model_rss_mb']:>14.0f}")
    print(f"speed-up: {ref['seconds_median'] / fast['seconds_median']:.0f}x wall (median), "
          f"{ref['cpu_seconds_median'] / fast['cpu_seconds_median']:.0f}x CPU time")
    print(f"max |keypoint difference|: {keypoint_diff:.2e} m; max relative gradient difference "
          f"(phenotypes, rotations, translations): {', '.join(f'{d:.1e}' for d in grad_diffs)}")


if __name__ == "__main__":
    main()
