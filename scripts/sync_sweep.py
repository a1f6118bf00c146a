"""How often the time offsets of unsynchronised views come out exact to the frame (``docs/capture.md``,
"Unsynchronised videos").

Each scene is a seeded synthetic capture (5-10 views, 2-4 people, 60-300 frames, mixed or seated behaviour) whose
cameras were started by hand: view v films the scene's frames from its own start frame (drawn in 0..60, at most half
the capture, so offsets up to +-2 s at 30 fps), numbered from 0. :func:`humancal.sync.estimate_time_offsets` then
estimates each view's offset from the detections alone. Per scene: the views exact to the frame, the views estimated
half a frame or more off but used (status ``ok``: silent errors), and the views refused (``ambiguous``, or
``unchecked``: one pair of views alone places it; :func:`humancal.sync.capture.synchronise_views` refuses both).

``--with-cameras`` does what ``humancal add --unsynced`` does next: the views with an offset (``ok``, ``unchecked``,
and ``ambiguous`` ones with a tentative offset, :func:`humancal.sync.tentative_offsets_s`) are put on one clock with
those offsets, calibrated from the people (intrinsics, extrinsics), and each offset is checked and moved (whole
frames and the fraction) with :func:`humancal.sync.check_offsets_with_cameras`; a view the cameras disagree with, or
are unsure of, is counted as refused (``add`` stops on it), an ``unchecked`` or tentative one they confirm (it
agrees, or moved inside the search) as used. Scenes with fewer than 3 such views are left as the estimate gave them.
``--no-tentative`` leaves ambiguous views out of the check, as ``add`` did before (the figures at 6ab35cb).
Where views disagree with the cameras, groups of views placed a period of the people's motion off are searched for
and checked again (:func:`humancal.sync.capture.check_and_regroup`); ``--no-regroup`` does not.

``--clocks consumer`` draws phone rigs instead (the ``phone`` preset: lens distortion, principal points off centre,
portrait images), each view filming at 25, 30, 50 or 60 fps, started up to 2 s apart, for 5-15 s; offsets are then
scored in view 0's frames.

``--seed S`` draws another set of scenes (scene ``i`` is seeded ``S * 100000 + i``; the default 0 gives the scenes
``docs/capture.md`` reports): tune on one seed, report on another.

Resumable: one JSON line per scene in ``--out``; a rerun skips the scenes already there.

    python scripts/sync_sweep.py --scenes 20 --seed 0 --out sync_sweep.jsonl [--lifter checkpoint.pt] [--with-cameras] \
        [--clocks consumer]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import pandas as pd


def _studio_scene(seed: int, body):
    """The default scenes: one frame rate (30 fps), cameras started up to 2 s apart; the scene, its detections on
    each view's own frames, each view's frame rate and true offset (seconds), and the row's description."""
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
    fps = np.full(views, config.fps)
    return scene, detections, fps, (starts - starts[0]) / config.fps, {"views": views, "people": people,
                                                                        "frames": frames, "behaviour": behaviour}


def _consumer_scene(seed: int, body, noise=None):
    """``--clocks consumer``: phones (the ``phone`` preset: k1 up to 0.1, principal points up to 5 % off centre,
    portrait two scenes in three) filming at 25, 30, 50 or 60 fps each, started up to 2 s apart, for 5-15 s;
    as :func:`_studio_scene`. ``noise``: another detector (a ``DetectorNoise``; None: the preset's)."""
    from humancal.synthetic import generate_scene, preset

    rng = np.random.default_rng(seed)
    views = int(rng.integers(5, 11))
    people = int(rng.integers(2, 5))
    frames = int(rng.integers(150, 451))
    behaviour = str(rng.choice(["mixed", "mixed", "seated"]))
    size = (1080, 1920) if rng.random() < 2 / 3 else (1920, 1080)
    config = preset("phone", num_views=views, num_people=people, num_frames=frames, seed=1000 + seed,
                    behaviour=behaviour, image_size_px=size, view_fps_choices=(25.0, 30.0, 50.0, 60.0))
    if noise is not None:
        config = config.replace(noise=noise)
    scene = generate_scene(config, body, sequence=f"sync_{seed}")
    clocks = scene.view_clocks
    return scene, scene.detections, clocks["fps"].to_numpy(), clocks["time_offset_s"].to_numpy(), {
        "views": views, "people": people, "frames": frames, "behaviour": behaviour,
        "fps": "/".join(f"{f:g}" for f in clocks["fps"])}


def run_scene(seed: int, body, lifter, with_cameras: bool = False, clocks: str = "studio", tentative: bool = True,
              signal: str = "lifted", check_interpolate: bool = True, regroup: bool = True) -> dict:
    from humancal.sync import SyncConfig, estimate_time_offsets

    scene, detections, fps, truth_s, row = (_consumer_scene if clocks == "consumer" else _studio_scene)(seed, body)
    truth = truth_s * fps[0]  # in reference frames (view 0's)
    start = time.perf_counter()
    estimate = estimate_time_offsets(detections, fps, lifter=lifter, config=SyncConfig(signal=signal))
    seconds = time.perf_counter() - start
    offsets, used = estimate.offset_frames, np.array([s == "ok" for s in estimate.status])
    if with_cameras:
        offsets, used, checked = _checked_with_cameras(detections, estimate, scene.rig, lifter, tentative,
                                                       check_interpolate, regroup)
        row |= checked
    used = used[1:]
    error = (offsets - truth)[1:]
    exact = used & (np.abs(error) < 0.5)
    views = row["views"]
    return row | {"seed": seed, "checked_views": views - 1, "exact": int(exact.sum()),
                  "wrong_used": int((used & ~exact).sum()), "ambiguous": int((~used).sum()),
                  "unchecked": estimate.status.count("unchecked"),
                  "max_error_used_frames": float(np.abs(error[used]).max()) if used.any() else None,
                  "errors_used_frames": [round(float(e), 3) for e in error[used]],
                  "view_errors_frames": [round(float(e), 3) if np.isfinite(e) else None for e in offsets - truth],
                  "view_used": [True] + [bool(u) for u in used],
                  "seconds": round(seconds, 2)}


def _checked_with_cameras(detections, estimate, rig, lifter, tentative=True, interpolate=True, regroup=True
                          ) -> tuple[np.ndarray, np.ndarray, dict]:
    """What ``humancal add --unsynced`` does after the estimate (``humancal.sync.capture.synchronise_views``): the
    views with an offset (``ok``, ``unchecked``, tentative) put on one clock, calibrated from the people and each
    offset checked and moved, views placed a period of the motion off regrouped where views disagree
    (:func:`humancal.sync.capture.check_and_regroup`). Returns the offsets (reference frames;
    NaN for a view the cameras disagree with), which views are used (``ok`` and neither disagreeing nor unsure, or
    ``unchecked`` or tentative and confirmed: the check agrees or moved it inside the search), and what the check
    did."""
    from humancal.sync import misplaced_period_s, tentative_offsets_s
    from humancal.sync.capture import check_and_regroup

    start = time.perf_counter()
    status = np.array(estimate.status)
    offset_s = tentative_offsets_s(estimate) if tentative else estimate.offset_s
    placed = [v for v, s in enumerate(status) if s in ("ok", "unchecked") or np.isfinite(offset_s[v])]
    offsets = offset_s * estimate.fps[0]
    used = status == "ok"
    if len(placed) < 3:
        return offsets, used, {"camera_check": "fewer than 3 views placed"}
    kept = detections[detections["view"].isin(placed)].copy()
    kept["view"] = kept["view"].map({v: i for i, v in enumerate(placed)})
    sizes = [(rig[v].width_px, rig[v].height_px) for v in placed]
    period_s = misplaced_period_s(estimate, offset_s) if regroup else None
    try:
        checked = check_and_regroup(kept, offset_s[placed], estimate.fps[placed], sizes, lifter, period_s,
                                    interpolate=interpolate)
    except Exception as error:  # noqa: BLE001 - the sweep records why a scene could not be checked
        return offsets, used, {"camera_check": f"{type(error).__name__}: {error}"}
    check = checked.check
    offsets[placed] = checked.offset_s * estimate.fps[0]
    verdict = np.array(check.status)
    refused = np.isin(verdict, ("disagrees", "unsure"))
    offsets[placed] = np.where(verdict == "disagrees", np.nan, offsets[placed] - check.shift)
    confirmed = np.array([check.confirms(i) for i in range(len(placed))])
    used[placed] = np.where(status[placed] == "ok", ~refused, confirmed)
    return offsets, used, {"camera_check": "ok", "check_views": placed,
                           "check_shift": [int(k) for k in check.shift_frames],
                           "check_sub_frame": [round(float(f), 3) for f in check.sub_frame],
                           "check_spread_frames": [round(float(f), 3) for f in check.spread_frames],
                           "check_status": list(check.status), "check_gain": [round(float(g), 3) for g in check.gain],
                           "check_level_m": [round(float(x), 4) for x in check.level_m],
                           "confirmed_unchecked": int((confirmed & (status[placed] == "unchecked")).sum()),
                           "period_s": None if period_s is None else round(period_s, 4),
                           "period_moved": [] if checked.period_search is None
                           else [int(k) for k in checked.period_search.shift_periods],
                           "regrouped": checked.regrouped,
                           "check_s": round(time.perf_counter() - start, 2)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0, help="which set of scenes (scene i: seed * 100000 + i)")
    parser.add_argument("--out", type=Path, default=Path("sync_sweep.jsonl"))
    parser.add_argument("--lifter", type=Path, default=None,
                        help="a lifter checkpoint (train_lifter.py --out) instead of the shipped weights")
    parser.add_argument("--clocks", choices=("studio", "consumer"), default="studio",
                        help="studio: one frame rate, the scenes docs/capture.md reports; consumer: phones at "
                             "25-60 fps filming 5-15 s")
    parser.add_argument("--with-cameras", action="store_true",
                        help="check the estimated offsets against cameras calibrated from the synchronised views")
    parser.add_argument("--no-tentative", dest="tentative", action="store_false",
                        help="with --with-cameras: ambiguous views are refused, not given a tentative offset for the "
                             "cameras to confirm (as humancal add did before 2026-11-29)")
    parser.add_argument("--check-nearest", dest="check_interpolate", action="store_false",
                        help="with --with-cameras: the check takes each view's nearest frames, not its people "
                             "interpolated at view 0's frame times (as before 2026-11-29)")
    parser.add_argument("--no-regroup", dest="regroup", action="store_false",
                        help="with --with-cameras: no search for views placed a period of the motion off when views "
                             "disagree with the cameras (as before 2026-11-30)")
    parser.add_argument("--signal", choices=("lifted", "2d", "both"), default="lifted",
                        help="the pose signal the offsets are estimated from (SyncConfig.signal)")
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
        row = run_scene(seed, body, lifter, args.with_cameras, args.clocks, args.tentative, args.signal,
                        args.check_interpolate, args.regroup)
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
