"""Random virtual cameras that look at one person the way cameras of real rigs do.

Each camera draws an image size, a focal length (within the focal range and the field-of-view range), a camera
height, an azimuth and a horizontal distance (within the distance range, narrowed so the person fills a
plausible fraction of the image height). A fraction ``steep_fraction`` of the cameras look down steeply instead:
their pitch is drawn, the distance is taken along the line of sight, and the height follows from both. Each
camera is first aimed at the person's pelvis with a small random roll, then turned so that the pelvis lands on a
random pixel: with probability ``truncation_prob`` anywhere in the image grown by ``centre_margin_frac`` on every
side (the body may be partly outside), otherwise uniformly where the whole body fits (a box from 0.5 apparent
heights above the pelvis to 0.55 below it, 0.3 to each side). The pitch varies with the camera height, the
distance and that pixel.
"""

from __future__ import annotations

import numpy as np

from humancal.camera import Camera, CameraRig, intrinsic_matrix, look_at
from humancal.lifter.config import VirtualCameraRanges
from humancal.lifter.features import R_crop_from_cam

__all__ = ["focal_limits_px", "sample_virtual_cameras"]


def focal_limits_px(width_px: int, ranges: VirtualCameraRanges) -> tuple[float, float]:
    """The focal lengths allowed for an image width: the focal range narrowed by the field-of-view range.

    Raises:
        ValueError: the two ranges do not overlap for this width.
    """
    fov_lo, fov_hi = np.radians(ranges.horizontal_fov_range_deg)
    low = max(ranges.focal_range_px[0], 0.5 * width_px / np.tan(0.5 * fov_hi))
    high = min(ranges.focal_range_px[1], 0.5 * width_px / np.tan(0.5 * fov_lo))
    if low > high:
        raise ValueError(
            f"no focal length in {ranges.focal_range_px} px gives a horizontal field of view in "
            f"{ranges.horizontal_fov_range_deg} deg for a {width_px} px wide image"
        )
    return float(low), float(high)


def sample_virtual_cameras(
    num_cameras: int,
    person_height_m: float,
    pelvis_height_m: float,
    ranges: VirtualCameraRanges,
    rng: np.random.Generator,
) -> CameraRig:
    """A virtual rig of cameras around a person standing near the world origin (Z up, floor z = 0).

    Args:
        num_cameras: how many cameras (>= 1).
        person_height_m: the person's standing height (sets the apparent size), metres.
        pelvis_height_m: height of the point the cameras aim at before the pixel shift, metres.
        ranges: the camera ranges.
        rng: source of randomness.

    Returns:
        the rig of ``num_cameras`` ideal pinhole cameras (square pixels, principal point at the image centre).

    Raises:
        ValueError: ``num_cameras`` < 1, a non-positive height, or ranges that admit no focal length.
    """
    if num_cameras < 1:
        raise ValueError(f"num_cameras={num_cameras} must be >= 1")
    if not (np.isfinite(person_height_m) and person_height_m > 0 and np.isfinite(pelvis_height_m)):
        raise ValueError(
            f"person_height_m={person_height_m} must be positive and pelvis_height_m={pelvis_height_m} finite"
        )
    cameras = []
    for _ in range(num_cameras):
        width, height = ranges.image_sizes_px[rng.integers(len(ranges.image_sizes_px))]
        focal = rng.uniform(*focal_limits_px(width, ranges))
        # Distance range narrowed by the apparent-size range; where they disagree the distance range wins.
        near = focal * person_height_m / (ranges.apparent_height_range[1] * height)
        far = focal * person_height_m / (ranges.apparent_height_range[0] * height)
        low, high = ranges.distance_range_m
        if max(low, near) <= min(high, far):
            low, high = max(low, near), min(high, far)
        distance = rng.uniform(low, high)
        azimuth = rng.uniform(0.0, 2.0 * np.pi)
        cam_height = rng.uniform(*ranges.camera_height_range_m)
        if rng.random() < ranges.steep_fraction:  # looking down steeply: distance along the line of sight
            pitch = np.radians(rng.uniform(*ranges.steep_pitch_range_deg))
            distance, cam_height = distance * np.cos(pitch), pelvis_height_m + distance * np.sin(pitch)
        roll = rng.normal(0.0, ranges.roll_std_deg)
        truncated = rng.random() < ranges.truncation_prob
        where = rng.random(2)

        centre = np.array([distance * np.cos(azimuth), distance * np.sin(azimuth), cam_height])
        size = np.array([width, height], dtype=np.float64)
        if truncated:
            low_px, high_px = -ranges.centre_margin_frac * size, (1.0 + ranges.centre_margin_frac) * size
        else:
            apparent_px = focal * person_height_m / np.hypot(distance, cam_height - pelvis_height_m)
            low_px = apparent_px * np.array([0.3, 0.5])
            high_px = size - apparent_px * np.array([0.3, 0.55])
            too_big = low_px > high_px  # the body does not fit along this axis: centre it there
            low_px, high_px = np.where(too_big, size / 2, low_px), np.where(too_big, size / 2, high_px)
        pixel = low_px + where * (high_px - low_px)
        K = intrinsic_matrix(focal, focal, width / 2.0, height / 2.0)
        R_aimed = look_at(centre, np.array([0.0, 0.0, pelvis_height_m]), roll_deg=float(roll))
        # Turn the camera so the aim point's ray (now the optical axis) becomes the ray through `pixel`.
        R_shift = R_crop_from_cam(pixel[None], K)[0].T
        cameras.append(Camera.from_center(K, R_shift @ R_aimed, centre, width, height))
    return CameraRig.from_cameras(cameras)
