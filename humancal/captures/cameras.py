"""The camera files that come with a user's capture: known cameras (used by the method) and reference cameras (the
truth, for evaluation only), read and matched to the capture's views.

A file holds one camera per view in view order, or, with ``views`` named, one camera per named view in the file's
order (a capture where only some cameras are known: one known camera fixes that camera and the world frame).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from humancal.camera import CameraRig, cameras_by_view, cameras_to_table
from humancal.camera.projection import undistort_points_px
from humancal.formats import CAMERA_READ_FORMATS, FormatError, infer_camera_format, read_cameras

__all__ = ["read_capture_cameras", "undistort_known_views"]


def _read(path: Path, fmt: str | None, sizes: Sequence[tuple[int, int]], format_option: str) -> CameraRig:
    if fmt is None:
        try:
            fmt = infer_camera_format(path)
        except FormatError:
            expected = (f"a camera file whose format its name tells (.toml, .json, .qca.txt, intri.yml, cameras.txt), "
                        f"or its format given with {format_option} (one of {list(CAMERA_READ_FORMATS)})")
            raise FormatError(path, None, expected, repr(path.name)) from None
    # EasyMocap files carry no image size: the cameras take the views' (one for all when they share it, so that a
    # camera count other than the views' is reported as such)
    options = {"image_size": sizes[0] if len(set(sizes)) == 1 else list(sizes)} if fmt == "easymocap" else {}
    return read_cameras(path, fmt, **options)


def read_capture_cameras(path: Path, fmt: str | None, sequence: str, view_names: Sequence[str],
                         sizes: Sequence[tuple[int, int]], *, views: Sequence[str] | None = None,
                         format_option: str = "cameras.format", views_option: str = "cameras.views") -> pd.DataFrame:
    """A capture's camera file as a canonical ``cameras`` table whose ``view`` column is the capture's view index.

    Args:
        path: the file.
        fmt: its format (None: from its name).
        sequence: the sequence name written in every row.
        view_names: (V,) the capture's view names.
        sizes: (V,) the views' image sizes (width_px, height_px).
        views: the names of the views the file's cameras belong to, in the file's order (None: every view, in view
            order).
        format_option, views_option: how messages name the options.

    Raises:
        FormatError: a bad file, a camera count other than the views', a view named twice or unknown, an image size
            other than its view's (naming the file and the camera).
    """
    cameras = _read(path, fmt, list(sizes), format_option)
    if views is None:
        targets = list(range(len(view_names)))
        expected = f"{len(view_names)} cameras (one per view, in view order)"
    else:
        unknown = [n for n in views if n not in view_names]
        if unknown or len(set(views)) != len(views):
            raise FormatError(path, views_option, f"distinct names of the capture's views {list(view_names)}",
                              repr(list(views)))
        targets = [list(view_names).index(n) for n in views]
        expected = f"{len(targets)} cameras (one per view of {views_option}, in that order)"
    if len(cameras) != len(targets):
        raise FormatError(path, None, expected, f"{len(cameras)} cameras")
    for k, (cam, v) in enumerate(zip(cameras, targets)):
        if (int(cam.width_px), int(cam.height_px)) != tuple(sizes[v]):
            raise FormatError(path, f"camera {k} image size",
                              f"the image size of view {v} ({view_names[v]}: {sizes[v][0]}x{sizes[v][1]})",
                              f"{cam.width_px}x{cam.height_px}")
    table = cameras_to_table(cameras, sequence)
    table["view"] = pd.array(targets, dtype=table["view"].dtype)
    return table


def undistort_known_views(detections: pd.DataFrame, known_cameras: pd.DataFrame) -> pd.DataFrame:
    """The detections of the views whose known camera distorts, moved to where that camera without its distortion
    sees them (the same ``K``): the method then works with pinholes, and the known cameras keep their lenses for
    the output. Other views' rows are unchanged.

    Args:
        detections: canonical ``detections`` (or ``lifted_detections``) table, pixels.
        known_cameras: canonical ``cameras`` table of the known views.
    """
    out = detections.copy()
    for view, camera in cameras_by_view(known_cameras).items():
        if not np.any(camera.distortion):
            continue
        rows = (out["view"] == view).to_numpy()
        moved = undistort_points_px(out.loc[rows, ["x_px", "y_px"]].to_numpy(), camera.K, camera.distortion)
        out.loc[rows, "x_px"], out.loc[rows, "y_px"] = moved[:, 0], moved[:, 1]
    return out
