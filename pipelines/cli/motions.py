"""``humancal export motions``: the stored fitted motions of a partition as BVH, glTF, npz or per-frame OBJ
files (``humancal.formats.motions``; ``docs/formats.md``, "Fitted motions")."""

from __future__ import annotations

import os
from collections.abc import Callable

import pandas as pd

__all__ = ["export_stored_motions"]


def _sequence_fps(partition: str) -> tuple[float, str]:
    """The frame rate of a partition's sequence and where it comes from (``humancal.datasets.inputs.sequence_fps``)."""
    from humancal.datasets.inputs import sequence_fps
    from pipelines.definitions import defs

    fps, source = sequence_fps(defs.resources["datasets"].spec(partition))
    return fps, source if "default" not in source else f"{source}; pass --fps to set it"


def _frame_slice(text: str | None) -> slice | None:
    """``A:B[:S]`` (sequence frame numbers, B excluded; each part may be empty) as a slice."""
    if text is None:
        return None
    parts = text.split(":")
    try:
        if len(parts) not in (2, 3):
            raise ValueError
        numbers = [int(p) if p.strip() else None for p in parts]
    except ValueError:
        raise SystemExit(f"humancal: --frames expects START:STOP[:STEP] frame numbers (e.g. 0:300:10), got {text!r}")
    return slice(*numbers)


def export_stored_motions(args, load_table: Callable[[], pd.DataFrame]) -> int:
    """Write the stored fitted motions of a partition as BVH, glTF, npz or per-frame OBJ files.

    Args:
        args: the parsed ``humancal export motions`` options.
        load_table: reads the partition's stored ``fitted_motions`` (called after the options are checked).
    """
    import torch
    from tqdm import tqdm

    from humancal.body import BodyModel
    from humancal.fitting import FittedMotions
    from humancal.formats.motions import MOTION_FORMATS, export_motions, mesh_selection, person_spans
    from pipelines.quiet_warp import init_warp_quietly

    if args.format not in MOTION_FORMATS:
        raise SystemExit(f"humancal: motions export supports --format {', '.join(MOTION_FORMATS)}; got {args.format}")
    frames = _frame_slice(args.frames)
    if frames is not None and args.format != "obj":
        raise SystemExit("humancal: --frames applies to --format obj only (the other formats hold every frame)")
    table = load_table()
    fps, source = (args.fps, "--fps") if args.fps is not None else _sequence_fps(args.partition)
    motions = FittedMotions.from_table(table, fps)
    print(f"{motions.num_people} people, frames {motions.frames[0]}-{motions.frames[-1]} at {fps:g} fps ({source})")
    torch.set_num_threads(max(1, min(4, os.cpu_count() or 1)))
    init_warp_quietly()  # anny's skinning initialises warp: no CUDA-driver warning on a CPU-only machine
    body = BodyModel()
    progress = None
    if args.format == "obj":
        total = sum(len(indices) for _, indices in mesh_selection(motions, frames))
        progress = tqdm(total=total, unit="mesh", desc="OBJ meshes")
    try:
        paths = export_motions(motions, body, args.format, args.out, sequence=args.partition, frames=frames,
                               progress=progress.update if progress is not None else None)
    finally:
        if progress is not None:
            progress.close()
    if args.format == "bvh":
        for span, path in zip(person_spans(motions), paths):
            print(f"person {span.person_id}: frames {motions.frames[span.first]}-{motions.frames[span.last]} -> {path}")
    else:
        print(f"wrote {len(paths)} file(s) under {args.out}" if len(paths) != 1 else f"wrote {paths[0]}")
    return 0
