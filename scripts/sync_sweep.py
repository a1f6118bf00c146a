"""How often the time offsets of unsynchronised views come out exact to the frame (``docs/capture.md``,
"Unsynchronised videos").

Each scene is a seeded synthetic capture (5-10 views, 2-4 people, 60-300 frames, mixed or seated behaviour) whose
cameras were started by hand: view v films the scene's frames from its own start frame (drawn in 0..60, at most half
the capture, so offsets up to +-2 s at 30 fps), numbered from 0. :func:`humancal.sync.estimate_time_offsets` then
estimates each view's offset from the detections alone. Per scene: the views exact to the frame, the views estimated
half a frame or more off but used (status ``ok``: silent errors), and the views refused (``ambiguous``, or
``unchecked``: one pair of views alone places it; :func:`humancal.sync.capture.synchronise_views` refuses both).

``--seed S`` draws another set of scenes (scene ``i`` is seeded ``S * 100000 + i``; the default 0 gives the scenes
``docs/capture.md`` reports): tune on one seed, report on another.

Resumable: one JSON line per scene in ``--out``; a rerun skips the scenes already there.

    python scripts/sync_sweep.py --scenes 20 --seed 0 --out sync_sweep.jsonl [--lifter checkpoint.pt]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import pandas as pd


def run_scene(seed: int, body, lifter) -> dict:
    from humancal.sync import estimate_time_offsets
    from humancal.synthetic import generate_scene, preset
    from humancal.synthetic.clocks import started_by_hand

    rng = np.random.default_rng(seed)
    views = int(rng.integers(5, 11))
    people = int(rng.integers(2, 5))
    frames = int(rng.integers(60, 301))
    behaviour = str(rng.choice(["mixed", "mixed", "seated"]))
    shift = min(60, frames // 2)
    starts = rng.integers(0, shift + 1, size=views)
    config = preset("demo", num_views=views, num_people=people, num_frames=frames + shift, seed=1000 + seed,
                    behaviour=behaviour)
    scene = generate_scene(config, body, sequence=f"sync_{seed}")
    detections = started_by_hand(scene.detections, starts, frames)
    truth = starts - starts[0]
    start = time.perf_counter()
    estimate = estimate_time_offsets(detections, config.fps, lifter=lifter)
    seconds = time.perf_counter() - start
    used = np.array([s == "ok" for s in estimate.status])[1:]
    error = (estimate.offset_frames - truth)[1:]
    exact = used & (np.abs(error) < 0.5)
    return {"seed": seed, "views": views, "people": people, "frames": frames, "behaviour": behaviour,
            "checked_views": views - 1, "exact": int(exact.sum()), "wrong_used": int((used & ~exact).sum()),
            "ambiguous": int((~used).sum()), "unchecked": estimate.status.count("unchecked"),
            "max_error_used_frames": float(np.abs(error[used]).max()) if used.any() else None,
            "seconds": round(seconds, 2)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0, help="which set of scenes (scene i: seed * 100000 + i)")
    parser.add_argument("--out", type=Path, default=Path("sync_sweep.jsonl"))
    parser.add_argument("--lifter", type=Path, default=None,
                        help="a lifter checkpoint (train_lifter.py --out) instead of the shipped weights")
    args = parser.parse_args()
    seeds = [args.seed * 100_000 + i for i in range(args.scenes)]

    import torch

    from humancal.body import BodyModel
    from humancal.lifter import load_lifter, shipped_checkpoint

    done = {}
    if args.out.exists():
        for line in args.out.read_text().splitlines():
            row = json.loads(line)
            done[row["seed"]] = row
    body, lifter = None, None
    for seed in seeds:
        if seed in done:
            continue
        if body is None:
            checkpoint = (torch.load(args.lifter, map_location="cpu", weights_only=True) if args.lifter
                          else shipped_checkpoint())
            body, lifter = BodyModel(), load_lifter(checkpoint)
        row = run_scene(seed, body, lifter)
        done[seed] = row
        with args.out.open("a") as f:
            f.write(json.dumps(row) + "\n")
    rows = pd.DataFrame([done[s] for s in seeds])
    print(rows.to_string(index=False))
    for label, part in (("all", rows), *((b, rows[rows["behaviour"] == b]) for b in ("mixed", "seated"))):
        n = part["checked_views"].sum()
        if n:
            print(f"{label}: {part['exact'].sum()}/{n} views exact to the frame ({part['exact'].sum() / n:.0%}), "
                  f"{part['wrong_used'].sum()} used but wrong, {part['ambiguous'].sum()} refused (ambiguous or unchecked)")


if __name__ == "__main__":
    main()
