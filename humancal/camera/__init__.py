"""Pinhole cameras in the house convention, stacked rigs, and their table form.

Convention (``docs/conventions.md``): OpenCV pinhole, x right, y down, z forward;
``x_cam = R_cam_from_world @ x_world + t_cam_from_world_m``; ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``
in pixels; distortion as OpenCV's (k1, k2, p1, p2, k3). World: metres, right-handed, Z up.

:mod:`.model` holds one camera (:class:`Camera`, :func:`project_points`, :func:`look_at`); :mod:`.rig` the
cameras of all views (:class:`CameraRig`, a sequence of cameras, and the canonical ``cameras`` table);
:mod:`.projection` the projection through OpenCV's camera model with lens distortion, in numpy and torch.

Example: a camera 5 m back along -y, looking along +y (world z up is its -y), sees the origin at its principal point
and a point 1 m up 200 px higher in the image:

    >>> import numpy as np
    >>> from humancal.camera import Camera, project_points
    >>> K = np.array([[1000.0, 0.0, 640.0], [0.0, 1000.0, 360.0], [0.0, 0.0, 1.0]])
    >>> R = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # rows: camera x, y, z in the world
    >>> camera = Camera.from_center(K, R, [0.0, -5.0, 0.0], 1280, 720)
    >>> pixels, depth = project_points(camera, np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    >>> pixels.round(6).tolist(), depth.tolist()
    ([[640.0, 360.0], [640.0, 160.0]], [5.0, 5.0])
"""

from humancal.camera.model import (
    Camera,
    intrinsic_matrices,
    intrinsic_matrix,
    look_at,
    pinhole,
    project_points,
)
from humancal.camera.rig import (
    CameraRig,
    RigTensors,
    cameras_by_view,
    cameras_from_table,
    cameras_to_table,
    sorted_views,
    with_known_distortion,
)

__all__ = [
    "Camera",
    "CameraRig",
    "RigTensors",
    "cameras_by_view",
    "cameras_from_table",
    "cameras_to_table",
    "intrinsic_matrices",
    "intrinsic_matrix",
    "look_at",
    "pinhole",
    "project_points",
    "sorted_views",
    "with_known_distortion",
]
