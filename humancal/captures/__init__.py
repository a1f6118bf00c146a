"""Users' own captures: per-view detector output (OpenPose JSON folders or COCO-style keypoint files) read into
the canonical tables, checked and summarised.

A capture is described by a :class:`CaptureConfig` (the options of a ``kind: capture`` sequence in a datasets
file)::

    format: openpose                  # or coco (AlphaPose, MMPose/RTMPose results, COCO annotation files)
    views: [cam1/, cam2/, cam3/]      # one folder (openpose) or file (coco) per view, in view order
    image_size: [1920, 1080]          # [width, height] for every view, or one pair per view
    skeleton: body25                  # optional where the array length tells it (needed for 25 points)
    cameras: {path: calib.toml, format: pose2sim}   # optional known cameras, used instead of a calibration
                                      # (views: [cam2]: the file's cameras are those views'; refine: true)
    reference_cameras: {path: truth.toml}           # optional true cameras: evaluation only
    drop_views: [cam3]                # optional: views left out
    fps: 30                           # optional (default 30 where a frame rate is needed)
    view_fps: {cam2: 60}              # optional: per-view frame rates (the others: fps)
    unsynced: true                    # optional: the videos were started by hand (time offsets estimated)
    time_offsets: {cam2: 1.25}        # optional: seconds, view v's frame n is at n / fps_v + offset_v
    videos: [cam1.mp4, cam2/, ...]    # optional: the footage, one video file or image folder per view (overlays,
                                      # viewer; never used by the method)

Relative paths are relative to the datasets file's folder. Reading a capture checks what was declared against the
detections (:func:`load_capture`: image sizes, a 25-point skeleton, the views), then drops (and counts) joints
outside the image (negative or beyond the width/height: trackers extrapolate a few, no detector saw them) and
placeholder person entries without keypoints; every problem is a :class:`~humancal.formats.FormatError` or
``ValueError`` naming the file and the field, or the view and the option. Unsynchronised views (``unsynced``,
``time_offsets``, ``view_fps``) are moved to view 0's frames (:mod:`humancal.sync`) before the views are checked
against each other. Known cameras become the
``known_cameras`` table (the method uses them); reference cameras the ``gt_cameras`` table (evaluation only).
"""

from humancal.captures.config import OPTION_NAMES, CaptureConfig
from humancal.captures.folder import CAPTURE_FILE, read_capture_folder
from humancal.captures.loading import Capture, CaptureSummary, load_capture, view_name
from humancal.captures.options import parse_image_size, parse_principal_point, principal_points_option

__all__ = ["CAPTURE_FILE", "OPTION_NAMES", "Capture", "CaptureConfig", "CaptureSummary", "load_capture",
           "parse_image_size", "parse_principal_point", "principal_points_option", "read_capture_folder",
           "view_name"]
