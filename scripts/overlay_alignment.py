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

import cv2
import numpy as np
import pandas as pd

from humancal.viewing import person_colour
from humancal.viewing.overlays import distance_to_colour, write_overlays
from humancal.viewing.reprojection import detection_people, reprojected_fit
from pipelines.view_command import capture_view


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
    people = detection_people(view.associations)
    rows = []
    with tempfile.TemporaryDirectory() as out:
        result = write_overlays(view, out, frames=frames, show_detections=False, max_width_px=100_000)
        for v, (name, camera, path) in enumerate(zip(view.view_names, view.cameras["final"], result.videos)):
            mine = view.detections[(view.detections["view"] == v) & (view.detections["score"] > 0)]
            fits = reprojected_fit(view.keypoints_world_m, v, camera, mine, people)
            by_frame = {int(f): rows for f, rows in mine.groupby("frame")}
            capture = cv2.VideoCapture(str(path))
            distances, errors = [], []
            for frame in result.frames:
                ok, image = capture.read()
                if not ok:
                    raise RuntimeError(f"{path}: frame {frame} missing")
                fit = fits.get(int(frame))
                if fit is not None and np.isfinite(fit.error_px):
                    errors.append(fit.error_px)
                for det_id, det in by_frame.get(int(frame), pd.DataFrame(columns=mine.columns)).groupby("det_id"):
                    person_id = people.get((int(frame), v, int(det_id)), -1)
                    if person_id >= 0 and fit is not None and person_id in fit.people:
                        distances += distance_to_colour(image, person_colour(person_id),
                                                        det[["x_px", "y_px"]].to_numpy()).tolist()
            capture.release()
            distances = np.asarray(distances)
            rows.append({"view": name, "frames": len(result.frames), "joints": len(distances),
                         "fit_error_px (median)": np.median(errors),
                         "detection_to_drawn_fit_px (median)": np.median(distances),
                         "p90": np.percentile(distances, 90),
                         "within_fit_error_plus_3px": np.mean(distances <= np.median(errors) + 3.0)})
    print(pd.DataFrame(rows).to_markdown(index=False, floatfmt=".2f"))


if __name__ == "__main__":
    main()
