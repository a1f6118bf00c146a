"""Files of other tools and datasets: keypoint formats, 2D detections, cameras.

* :mod:`humancal.formats.skeletons`: the keypoint formats (BODY_25, COCO-18, COCO-17, Halpe-26, SHELF15, ...).
* :mod:`humancal.formats.joint_mapping`: any skeleton to and from the canonical 23 joints, with the rules for
  derived joints (neck, mid-hip, Shelf head joints).
* :mod:`humancal.formats.detections`: OpenPose / COCO-style detection files <-> the canonical detections table.
* :mod:`humancal.formats.cameras`: camera files (humancal JSON, Shelf, Pose2Sim/anipose TOML, EasyMocap YAML,
  COLMAP text; Qualisys .qca.txt read only) <-> :class:`humancal.camera.CameraRig` rigs.

Every reader raises :class:`FormatError` (a ``ValueError``) with a one-line message naming the file, the field
and what was expected. Documentation with examples: ``docs/formats.md``.
"""

from humancal.formats.cameras import (
    CAMERA_FORMATS,
    CAMERA_READ_FORMATS,
    infer_camera_format,
    read_cameras,
    read_cameras_with_names,
    write_cameras,
)
from humancal.formats.detections import DETECTION_FORMATS, IMAGE_SIZE_ATTR, read_detections, write_openpose
from humancal.formats.errors import FormatError
from humancal.formats.joint_mapping import DERIVED_JOINTS, from_canonical, to_canonical
from humancal.formats.skeletons import SKELETONS, Skeleton, get_skeleton

__all__ = [
    "CAMERA_FORMATS",
    "CAMERA_READ_FORMATS",
    "DERIVED_JOINTS",
    "DETECTION_FORMATS",
    "IMAGE_SIZE_ATTR",
    "FormatError",
    "SKELETONS",
    "Skeleton",
    "from_canonical",
    "get_skeleton",
    "infer_camera_format",
    "read_cameras",
    "read_cameras_with_names",
    "read_detections",
    "to_canonical",
    "write_cameras",
    "write_openpose",
]
