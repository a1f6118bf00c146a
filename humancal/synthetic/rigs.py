"""Static camera rigs around the capture area: random rings and arcs, and the Human3.6M cameras.

Every camera has square pixels (unless ``focal_aspect_range`` draws fy / fx) and the principal point at the image
centre (unless ``principal_point_offset_px`` or ``principal_point_offset_max_frac`` moves it), is placed so that the
capture area fills about ``area_fill`` of its horizontal field of view (or, with ``camera_pitch_range_deg``, of the
image extent that binds at the drawn tilt), and is aimed at a point near the area centre at mid-body height
with a little random error in aim and roll. Lenses are ideal pinholes unless ``distortion_k1_range`` /
``distortion_k2_range`` ask for radial distortion (:mod:`humancal.synthetic.lenses`); the placement then makes sure
the area fits the distorted image too.
"""

from __future__ import annotations

import logging

import numpy as np

from humancal.camera import Camera, CameraRig, intrinsic_matrix, look_at
from humancal.settings import dataset_dir
from humancal.synthetic.config import SceneConfig
from humancal.synthetic.h36m_cameras import axes_meeting_point, load_h36m_cameras
from humancal.synthetic.lenses import LensDraws, distorted_radius, draw_lenses, fold_radius, undistorted_radius

__all__ = [
    "make_rig",
    "ring_rig",
    "dome_rig",
    "h36m_rig",
    "undistorted_radius",
    "monotonic_radius",
]

logger = logging.getLogger(__name__)

_AIM_HEIGHT_M = 1.0
"""Height of the aim point above the floor (mid-body), metres."""
_AIM_JITTER_M = 0.25
_ROLL_JITTER_DEG = 2.0
_BODY_RADIUS_M = 0.5
"""Added to the area's half-diagonal when fitting it into a field of view (arms and bodies at the edge)."""
_FIT_HEIGHT_M = 2.0
"""Height of the box fitted into the image by cameras with a drawn tilt (standing heads and raised hands)."""


def monotonic_radius(k1: float, k2: float = 0.0) -> float:
    """Largest undistorted radius (normalised image coordinates) up to which the radial model
    ``r_d = r (1 + k1 r^2 + k2 r^4)`` grows with ``r`` (:func:`humancal.synthetic.lenses.fold_radius`):
    ``1 / sqrt(-3 k1)`` for a k1-only barrel lens, inf for a lens that never folds.

    Beyond it a barrel lens model folds points from outside the field of view back into the image, so the
    detector treats such points as unseen.
    """
    return fold_radius(k1, k2)


def _fit_distance_m(
    config: SceneConfig, pitch_rad: float, half_extent: tuple[float, float], aim_world_m: np.ndarray
) -> float:
    """Distance from the aim point, along a line of sight tilted ``pitch_rad`` below the horizon, at which the
    box of the capture area (plus a body radius, from the floor to head height) spans ``area_fill`` of the
    image half-extent that binds (``half_extent``: undistorted normalised half-width and half-height)."""
    half = np.array(config.area_size_m) / 2.0 + _BODY_RADIUS_M
    corners = np.array(
        [[sx * half[0], sy * half[1], z] for sx in (-1, 1) for sy in (-1, 1) for z in (0.0, _FIT_HEIGHT_M)]
    )
    limit = config.area_fill * np.asarray(half_extent)
    # The box's extent seen at a given tilt barely depends on the azimuth of a ring camera (the area is a
    # rectangle, not a disc); the worst of four azimuths keeps every camera's fit on the safe side.
    def reaches(distance_m: float) -> float:
        worst = 0.0
        for azimuth in (0.0, 0.25 * np.pi, 0.5 * np.pi, 0.75 * np.pi):
            direction = np.array([np.cos(azimuth) * np.cos(pitch_rad), np.sin(azimuth) * np.cos(pitch_rad),
                                  np.sin(pitch_rad)])
            center = aim_world_m + distance_m * direction
            R = look_at(center, aim_world_m)
            x_cam = (corners - center) @ R.T
            if np.any(x_cam[:, 2] <= 0.1):
                return np.inf
            normalised = np.abs(x_cam[:, :2] / x_cam[:, 2:3]) / limit
            worst = max(worst, float(normalised.max()))
        return worst

    low, high = 0.5, 200.0
    for _ in range(50):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if reaches(mid) > 1.0 else (low, mid)
    return high


def ring_rig(config: SceneConfig, rng: np.random.Generator) -> CameraRig:
    """Cameras on a full circle (``"ring"``) or on an arc of ``arc_span_deg`` (``"arc"``) around the area.

    Azimuths are evenly spaced with a random jitter of a quarter spacing; each camera draws its focal length
    from ``focal_range_px`` and its height from ``camera_height_range_m``, then stands at the distance where
    the area (plus a body radius) spans ``area_fill`` of its horizontal field of view. With
    ``camera_pitch_range_deg`` set, each camera draws its tilt below the horizon instead of its height and
    stands on that line of sight through the aim point, at the distance where the box of the area (plus a
    body radius, floor to 2 m) spans ``area_fill`` of the binding image half-extent; its height follows.
    Each camera finally draws its lens (:func:`humancal.synthetic.lenses.draw_lenses`: k1, k2 and fy / fx, each only
    when its range asks for it); with ``horizontal_fov_range_deg`` the first draw is the field of view and the focal
    length follows from it through the lens. A pincushion lens (r_d > r) narrows the fields of view above to what its
    images show, a barrel lens leaves the placement of a pinhole (it only pulls the image points inwards) unless its
    model folds back inside the image.

    Args:
        config: the scene config (``rig`` must be ``"ring"`` or ``"arc"``).
        rng: source of randomness.

    Returns:
        the rig of ``config.num_views`` cameras.
    """
    num = config.num_views
    width, height = config.image_size_px
    if config.rig == "ring":
        spacing = 2 * np.pi / num
        azimuth = rng.uniform(0, 2 * np.pi) + spacing * np.arange(num)
    elif config.rig == "arc":
        span = np.radians(config.arc_span_deg)
        spacing = span / (num - 1)
        azimuth = rng.uniform(0, 2 * np.pi) - span / 2 + spacing * np.arange(num)
    else:
        raise ValueError(f"ring_rig: config.rig={config.rig!r} is not 'ring' or 'arc'")
    azimuth = azimuth + rng.uniform(-0.25, 0.25, num) * spacing
    focal = _draw_focal_or_fov(config, rng, num)
    tilted = config.camera_pitch_range_deg is not None
    if tilted:
        pitch = np.radians(rng.uniform(*config.camera_pitch_range_deg, num))
    else:
        cam_height = rng.uniform(*config.camera_height_range_m, num)
    targets, rolls = [], []
    for _ in range(num):
        targets.append(np.array([*rng.normal(0.0, _AIM_JITTER_M, 2), _AIM_HEIGHT_M + rng.normal(0.0, 0.1)]))
        rolls.append(float(rng.normal(0.0, _ROLL_JITTER_DEG)))
    lenses = draw_lenses(config.distortion_k1_range, config.distortion_k2_range, config.focal_aspect_range, num, rng)
    focal = _focal_from_fov(config, focal, lenses)
    distorted = lenses.distorted
    # Normalised half-width and half-height of the (undistorted) view that the image shows. A pincushion lens
    # (k1 > 0) pushes points outwards: it shows less, and the cameras step back. A barrel lens (k1 < 0) shows
    # more, but pulls the points inwards unevenly (more along the diagonal than the narrow side); the cameras
    # stand where a pinhole would, so the area fits either way, unless the lens model folds back on itself
    # inside the image (strong k1, wide lens): then only the view inside the fold radius counts.
    half_w, half_h = _half_extent(config, focal, lenses)
    cameras = []
    if tilted:
        nominal_aim = np.array([0.0, 0.0, _AIM_HEIGHT_M])
        for v in range(num):
            distance = _fit_distance_m(config, float(pitch[v]), (half_w[v], half_h[v]), nominal_aim)
            direction = np.array([np.cos(azimuth[v]) * np.cos(pitch[v]), np.sin(azimuth[v]) * np.cos(pitch[v]),
                                  np.sin(pitch[v])])
            center = targets[v] + distance * direction
            cameras.append(_camera(focal[v], lenses, v, center, targets[v], rolls[v], width, height))
        return CameraRig.from_cameras(cameras)
    radius = 0.5 * float(np.hypot(*config.area_size_m)) + _BODY_RADIUS_M
    half_fov = np.arctan(half_w) if distorted else np.arctan(width / (2.0 * focal))
    distance = radius / np.sin(config.area_fill * half_fov)
    for v in range(num):
        center = np.array([distance[v] * np.cos(azimuth[v]), distance[v] * np.sin(azimuth[v]), cam_height[v]])
        cameras.append(_camera(focal[v], lenses, v, center, targets[v], rolls[v], width, height))
    return CameraRig.from_cameras(cameras)


def dome_rig(config: SceneConfig, rng: np.random.Generator) -> CameraRig:
    """Cameras of a capture studio (``"dome"``): spread around the area at evenly spaced azimuths (a quarter
    spacing of jitter), each at an elevation drawn from ``config.dome_elevation_range_deg`` as seen from its aim
    point (knee height to overhead), at the distance where the box of the area (plus a body radius, floor to 2 m)
    spans ``area_fill`` of its binding image half-extent. A camera that would stand lower than 0.3 m above the
    floor is raised to it along its line of sight's elevation. Lenses as in :func:`ring_rig`.

    Returns:
        the rig of ``config.num_views`` cameras.
    """
    num = config.num_views
    width, height = config.image_size_px
    spacing = 2 * np.pi / num
    azimuth = rng.uniform(0, 2 * np.pi) + spacing * (np.arange(num) + rng.uniform(-0.25, 0.25, num))
    elevation = np.radians(rng.uniform(*config.dome_elevation_range_deg, num))
    focal = _draw_focal_or_fov(config, rng, num)
    lenses = draw_lenses(config.distortion_k1_range, config.distortion_k2_range, config.focal_aspect_range, num, rng)
    focal = _focal_from_fov(config, focal, lenses)
    half_w, half_h = _half_extent(config, focal, lenses)
    cameras = []
    for v in range(num):
        target = np.array([*rng.normal(0.0, _AIM_JITTER_M, 2), _AIM_HEIGHT_M + rng.normal(0.0, 0.1)])
        roll = float(rng.normal(0.0, _ROLL_JITTER_DEG))
        distance = _fit_distance_m(config, float(elevation[v]), (half_w[v], half_h[v]), target)
        if target[2] + distance * np.sin(elevation[v]) < 0.3:  # not below the floor: raise it to 0.3 m
            elevation[v] = np.arcsin((0.3 - target[2]) / distance)
            distance = _fit_distance_m(config, float(elevation[v]), (half_w[v], half_h[v]), target)
        direction = np.array([np.cos(azimuth[v]) * np.cos(elevation[v]), np.sin(azimuth[v]) * np.cos(elevation[v]),
                              np.sin(elevation[v])])
        cameras.append(_camera(focal[v], lenses, v, target + distance * direction, target, roll, width, height))
    return CameraRig.from_cameras(cameras)


def _far_cameras(cameras: CameraRig, config: SceneConfig, rng: np.random.Generator) -> CameraRig:
    """The last ``config.far_views`` cameras moved back along their optical axes to ``far_distance_factor`` times
    their distance from the area centre (at mid-body height), their focal lengths multiplied by the same factor
    (no draw when there are none: the other scenes keep their random stream)."""
    if config.far_views == 0:
        return cameras
    factor = rng.uniform(*config.far_distance_factor, config.far_views)
    moved = list(cameras)
    centre = np.array([0.0, 0.0, _AIM_HEIGHT_M])
    for k, v in enumerate(range(len(cameras) - config.far_views, len(cameras))):
        c = cameras[v]
        forward = c.R_cam_from_world[2]
        depth = float(forward @ (centre - c.center_world_m))
        K = c.K.copy()
        K[0, 0] *= factor[k]
        K[1, 1] *= factor[k]
        center = c.center_world_m - (factor[k] - 1.0) * depth * forward
        far = Camera.from_center(K, c.R_cam_from_world, center, c.width_px, c.height_px)
        moved[v] = Camera(far.K, far.R_cam_from_world, far.t_cam_from_world_m, c.width_px, c.height_px, c.distortion)
    return CameraRig.from_cameras(moved)


def _draw_focal_or_fov(config: SceneConfig, rng: np.random.Generator, num: int) -> np.ndarray:
    """(V,) drawn focal lengths, pixels, or, with ``horizontal_fov_range_deg``, drawn horizontal fields of view,
    degrees (turned into focal lengths by :func:`_focal_from_fov` once the lenses are drawn); one draw either way."""
    drawn_range = config.horizontal_fov_range_deg or config.focal_range_px
    return rng.uniform(*drawn_range, num)


def _focal_from_fov(config: SceneConfig, drawn: np.ndarray, lenses: LensDraws) -> np.ndarray:
    """(V,) focal lengths fx, pixels: ``drawn`` itself, or the focal at which each drawn horizontal field of view
    (degrees) reaches the image's left and right edges through the camera's lens."""
    if config.horizontal_fov_range_deg is None:
        return drawn
    half_width = distorted_radius(np.tan(np.radians(drawn) / 2.0), lenses.k1, lenses.k2)
    return config.image_size_px[0] / (2.0 * half_width)


def _half_extent(config: SceneConfig, focal_px: np.ndarray, lenses: LensDraws) -> tuple[np.ndarray, np.ndarray]:
    """(V,) undistorted normalised half-width and half-height of the view each camera's image shows along its axes.

    Through a lens, the image's edges lie at the undistorted radii of the distorted ones. A pincushion lens shows
    less than a pinhole of its focal; a barrel lens shows more, but pulls the points inwards unevenly (more along the
    diagonal than along the axes), so by default the cameras keep the pinhole's extent (the area fits either way).
    With ``horizontal_fov_range_deg`` the field of view through the lens is what was asked for, and the placement
    uses it.
    """
    width, height = config.image_size_px
    half_w, half_h = width / (2.0 * focal_px), height / (2.0 * (focal_px * lenses.aspect))
    if not lenses.distorted:
        return half_w, half_h
    through_w = undistorted_radius(half_w, lenses.k1, lenses.k2)
    through_h = undistorted_radius(half_h, lenses.k1, lenses.k2)
    if config.horizontal_fov_range_deg is not None:
        return through_w, through_h
    return np.minimum(through_w, half_w), np.minimum(through_h, half_h)


def _with_lens(K: np.ndarray, lenses: LensDraws, v: int) -> tuple[np.ndarray, ...]:
    """Camera ``v``'s ``K`` with fy = aspect * fx (unchanged for square pixels), and its (5,) distortion."""
    K = K.copy()
    K[1, 1] = K[0, 0] * lenses.aspect[v]
    return K, lenses.distortion(v)


def _camera(focal_px: float, lenses: LensDraws, v: int, center: np.ndarray, target: np.ndarray, roll_deg: float,
            width: int, height: int) -> Camera:
    R = look_at(center, target, roll_deg=roll_deg)
    K, distortion = _with_lens(intrinsic_matrix(focal_px, focal_px, width / 2.0, height / 2.0), lenses, v)
    camera = Camera.from_center(K, R, center, width, height)
    return Camera(camera.K, camera.R_cam_from_world, camera.t_cam_from_world_m, width, height, distortion)


def h36m_rig(config: SceneConfig) -> CameraRig:
    """The Human3.6M cameras of ``config.h36m_subject`` (the first ``num_views`` in file order).

    Human3.6M's world is already Z up with the floor at z = 0; it is converted from millimetres to metres
    and shifted horizontally so that the point the cameras look at lies above the origin (the centre of
    our capture area). The measured focal lengths are kept (about 1145 px), the principal point is put at
    the centre of ``config.image_size_px`` and the file's lens distortion is dropped (:func:`make_rig` gives
    the cameras a drawn k1 when ``distortion_k1_range`` asks for one).

    Raises:
        humancal.settings.DataRootError: the data root or its ``h36m_cameras`` folder is missing.
        ValueError: the calibration file is malformed.
    """
    folder = dataset_dir("h36m_cameras", required_for="the synthetic rig 'h36m'")
    cameras_raw = load_h36m_cameras(folder / "camera-parameters.json", config.h36m_subject)
    R = np.stack([c[2] for c in cameras_raw])
    t = np.stack([c[3] for c in cameras_raw])
    centers = -np.einsum("vji,vj->vi", R, t)
    shift = axes_meeting_point(centers, R[:, 2, :])
    shift[2] = 0.0
    width, height = config.image_size_px
    cameras = []
    for (camera_id, K_raw, R_v, _), center in zip(cameras_raw[: config.num_views], centers):
        focal = 0.5 * (K_raw[0, 0] + K_raw[1, 1])
        cameras.append(Camera.from_center(intrinsic_matrix(focal, focal, width / 2.0, height / 2.0), R_v, center - shift, width, height))
        logger.debug("h36m camera %s: focal %.1f px, centre %s m", camera_id, focal, np.round(center - shift, 3))
    return CameraRig.from_cameras(cameras)


def make_rig(config: SceneConfig, rng: np.random.Generator) -> CameraRig:
    """The cameras of ``config.rig`` (see :func:`ring_rig`, :func:`dome_rig`, :func:`h36m_rig`), the last
    ``config.far_views`` of them moved far back with zoom lenses.

    Raises:
        ValueError: unknown rig kind.
        humancal.settings.DataRootError: rig ``"h36m"`` without the data root.
    """
    if config.rig in ("ring", "arc"):
        cameras = ring_rig(config, rng)
    elif config.rig == "dome":
        cameras = dome_rig(config, rng)
    elif config.rig == "h36m":
        cameras = h36m_rig(config)
        lenses = draw_lenses(config.distortion_k1_range, config.distortion_k2_range, config.focal_aspect_range,
                             len(cameras), rng)
        with_lenses = []
        for v, c in enumerate(cameras):
            K, distortion = _with_lens(c.K, lenses, v)
            with_lenses.append(Camera(K, c.R_cam_from_world, c.t_cam_from_world_m, c.width_px, c.height_px, distortion))
        cameras = CameraRig.from_cameras(with_lenses)
    else:
        raise ValueError(f"SceneConfig.rig={config.rig!r} is unknown; allowed: 'ring', 'arc', 'dome', 'h36m'")
    cameras = _far_cameras(cameras, config, rng)
    cameras = _offset_principal_points(cameras, config.principal_point_offset_px, rng)
    return _shift_principal_points(cameras, config.principal_point_offset_max_frac, rng)


def _offset_principal_points(cameras: CameraRig, offset_px: float, rng: np.random.Generator) -> CameraRig:
    """The cameras with their principal points ``offset_px`` from where they were, each in a drawn direction (no
    draw when 0: the scenes without an offset keep their random stream)."""
    if offset_px == 0.0:
        return cameras
    angle = rng.uniform(0.0, 2.0 * np.pi, len(cameras))
    moved = []
    for c, a in zip(cameras, angle):
        K = c.K.copy()
        K[:2, 2] += offset_px * np.array([np.cos(a), np.sin(a)])
        moved.append(Camera(K, c.R_cam_from_world, c.t_cam_from_world_m, c.width_px, c.height_px, c.distortion))
    return CameraRig.from_cameras(moved)


def _shift_principal_points(cameras: CameraRig, max_frac: float, rng: np.random.Generator) -> CameraRig:
    """The cameras with their principal points moved by ``(u_x width, u_y height)``, ``u`` uniform in
    ``[-max_frac, max_frac]`` per axis and camera (no draw when 0: the scenes without it keep their random stream)."""
    if max_frac == 0.0:
        return cameras
    fraction = rng.uniform(-max_frac, max_frac, (len(cameras), 2))
    moved = []
    for c, u in zip(cameras, fraction):
        K = c.K.copy()
        K[:2, 2] += u * np.array([c.width_px, c.height_px])
        moved.append(Camera(K, c.R_cam_from_world, c.t_cam_from_world_m, c.width_px, c.height_px, c.distortion))
    return CameraRig.from_cameras(moved)
