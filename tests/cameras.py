"""Cameras for unit tests: a ring of pinhole cameras looking at the origin."""

import numpy as np

from humancal.camera import Camera


def ring_of_cameras(num_views: int, radius_m: float, height_m: float, focal_px: float = 1200.0,
                    width_px: int = 1920, height_px: int = 1080) -> list[Camera]:
    """``num_views`` cameras evenly spaced on a circle of ``radius_m`` around the z axis, ``height_m`` up, each
    looking at the origin with a level x axis; principal point at the image centre, no distortion."""
    cameras = []
    for v in range(num_views):
        angle = 2 * np.pi * v / num_views
        centre = np.array([radius_m * np.cos(angle), radius_m * np.sin(angle), height_m])
        z = -centre / np.linalg.norm(centre)
        x = np.cross(z, [0.0, 0.0, 1.0])
        x /= np.linalg.norm(x)
        K = np.array([[focal_px, 0, width_px / 2], [0, focal_px, height_px / 2], [0, 0, 1]])
        cameras.append(Camera.from_center(K, np.stack([x, np.cross(z, x), z]), centre, width_px, height_px))
    return cameras
