"""How well the overlays sit on the footage, measured on the written video frames.

Writes the partition's overlays with the reprojected fit only (``humancal export overlays --no-detections``) on the
given footage at full resolution, reads every frame back, and reports per view: the median distance from each
associated detection's joints to the nearest pixel drawn in its person's colour, beside the fit's median
reprojection error (the distance from the fitted joints to the detections). A drawn fit that sits where it
should is at most the fit's error (plus half a line) away from the detections.

    python scripts/overlay_alignment.py --partition synthetic__demo --videos FOOTAGE_DIR [--frames 0:300:10]
"""

from __future__ import annotations

import argparse
import tempfile

import numpy as np

from humancal.viewing.overlays import overlay_alignment, write_overlays
from pipelines.cli.view import capture_view


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--partition", required=True)
    parser.add_argument("--videos", nargs="+", required=True, help="as `humancal export overlays --videos`")
    parser.add_argument("--frames", default="0:1000000:10", help="START:STOP:STEP of the frames measured")
    args = parser.parse_args()
    start, stop, step = (int(p) for p in args.frames.split(":"))
    view = capture_view(args.partition, meshes=False, videos=args.videos)
    numbers = np.asarray(sorted(view.detections["frame"].unique()))
    frames = numbers[(numbers >= start) & (numbers < stop) & ((numbers - start) % step == 0)]
    with tempfile.TemporaryDirectory() as out:
        result = write_overlays(view, out, frames=frames, show_detections=False, max_width_px=100_000)
        table = overlay_alignment(view, result)
    print(table.to_markdown(index=False, floatfmt=".2f"))


if __name__ == "__main__":
    main()
