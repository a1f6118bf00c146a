"""The names of the file formats and skeletons, for the command-line parser.

``humancal --help`` and argument errors must not import numpy, torch or Dagster (``humancal.formats`` imports all
of the readers), so the parser takes its choices from here. ``tests/pipelines/test_cli.py`` checks that these are
the names ``humancal.formats`` defines.
"""

CAMERA_FORMATS = ("humancal", "shelf", "pose2sim", "anipose", "easymocap", "colmap")
"""``humancal.formats.CAMERA_FORMATS`` (the formats cameras are written in)."""

CAMERA_READ_FORMATS = (*CAMERA_FORMATS, "qualisys")
"""``humancal.formats.cameras.CAMERA_READ_FORMATS`` (the formats cameras are read from)."""

MOTION_FORMATS = ("bvh", "gltf", "npz", "obj")
"""``humancal.formats.motions.MOTION_FORMATS``."""

OPENPOSE_SKELETONS = ("body25", "body25b", "coco18")
"""``humancal.formats.detections.OPENPOSE_SKELETONS``."""

COCO_SKELETONS = ("coco17", "halpe26", "coco_wholebody133")
"""``humancal.formats.detections.COCO_SKELETONS``."""
