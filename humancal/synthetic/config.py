"""Configuration of a synthetic scene (:class:`SceneConfig`); its detector model, :class:`DetectorNoise`, lives in
:mod:`humancal.synthetic.detector_noise` (importable from here too).

A frozen dataclass validated on construction: a bad value raises a one-line ``ValueError`` naming the field, the
value received and the allowed range. Every length is in metres, every image quantity in pixels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

from humancal.config import Config, Range, in_range, ordered_pair
from humancal.synthetic.detector_noise import DetectorNoise
from humancal.synthetic.lenses import distorted_radius, fits_monotonic, fold_radius

__all__ = [
    "RigKind",
    "RIG_KINDS",
    "Behaviour",
    "BEHAVIOURS",
    "DetectorNoise",
    "SceneConfig",
    "MAX_PEOPLE",
    "MIN_VIEWS",
    "MAX_VIEWS",
    "FOCAL_LIMITS_PX",
    "IMAGE_SIZE_LIMITS_PX",
    "K1_LIMITS",
    "K2_LIMITS",
    "FOCAL_ASPECT_LIMITS",
    "PRINCIPAL_POINT_FRAC_LIMIT",
    "FOV_LIMITS_DEG",
    "TIME_OFFSET_LIMITS_S",
    "VIEW_FPS_LIMITS",
    "PITCH_LIMITS_DEG",
    "OUT_OF_VIEW_DURATION_S",
]

RigKind = Literal["ring", "arc", "dome", "h36m"]
RIG_KINDS: tuple[str, ...] = ("ring", "arc", "dome", "h36m")
"""Camera rig layouts: a full circle, a partial circle, or the four Human3.6M cameras (external data)."""
Behaviour = Literal["mixed", "seated", "low"]
BEHAVIOURS: tuple[str, ...] = ("mixed", "seated", "low")
"""What the people do: a mix of mostly upright activities, sitting all the time, or mostly off their feet."""

MAX_PEOPLE = 8
MIN_VIEWS, MAX_VIEWS = 2, 31
FOCAL_LIMITS_PX = (500.0, 2500.0)
"""Allowed focal lengths, pixels."""
IMAGE_SIZE_LIMITS_PX = ((480, 480), (1920, 1920))
"""Smallest and largest allowed image (width, height), pixels: each side in [480, 1920], landscape or portrait."""
K1_LIMITS = (-0.5, 0.5)
"""Allowed radial distortion coefficient k1 (OpenCV model, normalised image coordinates)."""
K2_LIMITS = (-0.5, 0.5)
"""Allowed radial distortion coefficient k2 (OpenCV model, normalised image coordinates)."""
FOCAL_ASPECT_LIMITS = (0.98, 1.02)
"""Allowed focal aspect ``fy / fx`` (``focal_aspect_range``): non-square pixels or a resampled video, up to 2 %."""
PRINCIPAL_POINT_FRAC_LIMIT = 0.1
"""Largest principal point offset per image axis, fraction of the image width or height
(``principal_point_offset_max_frac``)."""
FOV_LIMITS_DEG = (30.0, 160.0)
"""Allowed horizontal field of view through the lens, degrees (``horizontal_fov_range_deg``)."""
TIME_OFFSET_LIMITS_S = (-2.0, 2.0)
"""Allowed time offset of a view's frame 0 on the reference clock, seconds (``time_offset_range_s``)."""
VIEW_FPS_LIMITS = (1.0, 1000.0)
"""Allowed per-view frame rates, frames per second (``view_fps_choices``)."""
PITCH_LIMITS_DEG = (0.0, 75.0)
"""Allowed angle of a camera's optical axis below the horizon, degrees (``camera_pitch_range_deg``)."""
OUT_OF_VIEW_DURATION_S = (1.0, 4.0)
"""How long a person stays out of every view in one spell (``out_of_view_spells``), seconds (uniform)."""
_AREA_PER_PERSON_M2 = 2.0
"""Floor area each person needs to walk about without constant collisions, square metres."""
_OWNER = "SceneConfig"


@dataclass(frozen=True)
class SceneConfig(Config):
    """Everything that defines a synthetic scene; the same config (seed included) gives the same scene.

    Attributes:
        num_people: people in the scene, 1..8.
        num_views: static cameras, 2..31 (at most 4 for the ``"h36m"`` rig).
        num_frames: frames to generate, >= 1.
        fps: frame rate, frames per second (default 30).
        seed: seed of the one ``numpy.random.Generator`` every random choice comes from (>= 0).
        rig: camera layout: ``"ring"`` (full circle), ``"arc"`` (partial circle, ``arc_span_deg``), ``"dome"``
            (a capture studio: cameras spread over a dome around a small area, from knee height to overhead,
            each looking at its centre: ``dome_elevation_range_deg``) or ``"h36m"`` (the Human3.6M cameras, read
            from the data root).
        h36m_subject: which subject's calibration of the Human3.6M rig to use (``"S1"`` .. ``"S11"``).
        focal_range_px: (min, max) focal length fx = fy, pixels, within [500, 2500]; each camera draws one.
            Ignored by the ``"h36m"`` rig, which keeps its measured focal lengths.
        image_size_px: (width, height) of every image, pixels, each side in [480, 1920]: landscape
            (1920, 1080) or portrait (1080, 1920) alike.
        area_size_m: (x, y) size of the rectangular capture area centred on the world origin, metres; people's
            roots stay inside it.
        camera_height_range_m: (min, max) height of the camera centres above the floor, metres, within
            [0.3, 10]. Ignored when ``camera_pitch_range_deg`` is set.
        camera_pitch_range_deg: None (default: each camera's height is drawn from ``camera_height_range_m``
            and its downward tilt follows), or (min, max) angle of the optical axis below the horizon,
            degrees, within [0, 75]: each camera draws its tilt from it and stands on that line of sight
            from the aim point, at the distance where the capture area fits its image; its height follows
            (e.g. 7.5-13 m at 50-60 degrees for the default area and lenses, less with wider lenses).
        area_fill: fraction of the horizontal field of view the capture area spans (sets each camera's
            distance from its focal length), in [0.3, 1.2]; above 1 the area's edges leave the images. With
            ``camera_pitch_range_deg`` set: the fraction of the image half-width or half-height (whichever
            binds) that the farthest corner of the area reaches.
        arc_span_deg: angle covered by the cameras of an ``"arc"`` rig, degrees, in [30, 330].
        height_range_m: (min, max) standing height of the people, metres, within [1.4, 2.0].
        noise: the detector model.
        behaviour: what the people do (``docs/synthetic.md``, "Motions"): ``"mixed"`` (walk, turn, stand,
            gesture, crouch; the default), ``"seated"`` (everyone sits on an invisible chair at a fixed spot for
            the whole capture, with upper-body activity) or ``"low"`` (mostly off their feet: sit, crouch and
            bend, with short walks and a little standing between).
        distortion_k1_range: (min, max) radial distortion k1 of the lenses, within [-0.5, 0.5]; each camera
            draws its k1 uniformly (stored in ``Camera.distortion``, the detections are projected through
            it). (0, 0), the default, gives ideal pinholes.
        out_of_view_spells: mean number of spells per person (Poisson) in which the person is out of every
            camera's view (gone through a door, behind a wall), each lasting ``OUT_OF_VIEW_DURATION_S``; no view
            detects the person then, and the person comes back wherever the motion has meanwhile taken them. A
            spell may overlap the start or the end (someone who enters late or leaves early). In [0, 5]; 0, the
            default, keeps everyone in the capture all along.
        dome_elevation_range_deg: (min, max) elevation of the ``"dome"`` rig's cameras seen from the aim point,
            degrees, within [-20, 80]: each camera draws one (0: level with the aim point at mid-body height).
        far_views: this many cameras (the last ones of the rig) stand ``far_distance_factor`` times farther from
            the area than the rig places them, with their focal length multiplied by the same factor (a zoom lens
            across a hall: the people keep their size in the image, the camera is nearly affine). In [0, 4],
            fewer than ``num_views``; not with ``"h36m"``.
        far_distance_factor: (min, max) of the far cameras' distance (and focal) factor, within [1.2, 6].
        principal_point_offset_px: each camera's principal point is moved this far from the image centre, pixels,
            in a direction drawn per camera (real rigs: Human3.6M 12-20 px, Shelf 13-52 px). In [0, 200]; 0, the
            default, keeps it at the centre, where the calibration assumes it.
        distortion_k2_range: (min, max) radial distortion k2 of the lenses, within [-0.5, 0.5]; each camera draws its
            k2 uniformly after its k1 (an action camera: k1 about -0.3 with k2 about 0.1). (0, 0), the default, gives
            k1-only lenses. Other than (0, 0), the lens must stay one-to-one over the whole image: the lens of the
            smallest k1 and k2 (the first to fold) must reach beyond the image corner at the shortest focal (or
            widest field of view).
        focal_aspect_range: (min, max) focal aspect ``fy / fx`` within [0.98, 1.02]; each camera draws one (fx from
            ``focal_range_px``, fy = aspect * fx). (1, 1), the default, gives square pixels.
        principal_point_offset_max_frac: each camera's principal point is moved by ``(u_x width, u_y height)`` with
            ``u_x``, ``u_y`` drawn uniformly in [-max, max] (a phone's or action camera's sensor crop: up to 5 % of the
            image off centre). In [0, 0.1]; 0, the default, draws nothing. Not together with
            ``principal_point_offset_px``.
        horizontal_fov_range_deg: None (default: each camera draws its focal length from ``focal_range_px``), or
            (min, max) horizontal field of view through the lens, degrees, within [30, 160]: each camera draws one and
            its focal length follows from it and its lens (``fx = (width / 2) / r_d(tan(fov / 2))`` with ``r_d`` the
            lens's radial model), so a wide barrel lens gets the field of view it is sold with. Not for ``"h36m"``.
        time_offset_range_s: (min, max) time offset of each view except view 0, seconds, within [-2, 2]: view ``v``'s
            frame ``n`` is taken at reference time ``n / fps_v + offset_v`` (``offset_v``: the reference time of its
            frame 0; view 0 is the reference clock, offset 0). (0, 0), the default, keeps every view synchronised.
        view_fps_choices: None (default: every view films at ``fps``) or the frame rates, frames per second, each view
            draws one from uniformly (e.g. (25, 30, 50, 60)); 1 to 8 values in [1, 1000]. The ground truth stays on the
            reference clock (``fps``, frame 0 at t = 0); each view's detections carry its own frame numbers
            (``docs/synthetic.md``, "Unsynchronised videos").
    """

    num_people: int = field(default=4, metadata=in_range(1, MAX_PEOPLE, integer=True))
    num_views: int = field(default=5, metadata=in_range(MIN_VIEWS, MAX_VIEWS, integer=True))
    num_frames: int = field(default=300, metadata=in_range(1, 1_000_000, integer=True))
    fps: float = field(default=30.0, metadata=in_range(1, 1000))
    seed: int = field(default=0, metadata=in_range(0, 2**63 - 1, integer=True))
    rig: RigKind = "ring"
    h36m_subject: str = "S1"
    focal_range_px: tuple[float, float] = (900.0, 1600.0)
    image_size_px: tuple[int, int] = (1920, 1080)
    area_size_m: tuple[float, float] = (5.0, 4.0)
    camera_height_range_m: tuple[float, float] = (1.5, 4.0)
    area_fill: float = field(default=0.9, metadata=in_range(0.3, 1.2))
    arc_span_deg: float = field(default=150.0, metadata=in_range(30, 330))
    height_range_m: tuple[float, float] = (1.5, 1.95)
    noise: DetectorNoise = field(default_factory=DetectorNoise)
    behaviour: Behaviour = "mixed"
    distortion_k1_range: tuple[float, float] = (0.0, 0.0)
    camera_pitch_range_deg: tuple[float, float] | None = None
    out_of_view_spells: float = field(default=0.0, metadata=in_range(0, 5))
    principal_point_offset_px: float = field(default=0.0, metadata=in_range(0, 200))
    dome_elevation_range_deg: tuple[float, float] = (-5.0, 55.0)
    far_views: int = field(default=0, metadata=in_range(0, 4, integer=True))
    far_distance_factor: tuple[float, float] = (2.0, 4.0)
    distortion_k2_range: tuple[float, float] = (0.0, 0.0)
    focal_aspect_range: tuple[float, float] = (1.0, 1.0)
    principal_point_offset_max_frac: float = field(default=0.0, metadata=in_range(0, PRINCIPAL_POINT_FRAC_LIMIT))
    horizontal_fov_range_deg: tuple[float, float] | None = None
    time_offset_range_s: tuple[float, float] = (0.0, 0.0)
    view_fps_choices: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        self._check_counts()
        focal = ordered_pair(_OWNER, "focal_range_px", self.focal_range_px, *FOCAL_LIMITS_PX)
        size = _checked_image_size(self.image_size_px)
        normalised: dict[str, object] = {"focal_range_px": focal, "image_size_px": size,
                                         "area_size_m": _checked_area(self.area_size_m, self.num_people)}
        normalised.update(self._checked_layout())
        normalised.update(self._checked_lenses(focal, size))
        normalised.update(self._checked_clocks())
        normalised["fps"] = float(self.fps)
        normalised["principal_point_offset_px"] = float(self.principal_point_offset_px)
        # Normalise containers to tuples of floats/ints so that equal configs compare and hash equal.
        for name, value in normalised.items():
            object.__setattr__(self, name, value)

    def _check_counts(self) -> None:
        """Check the rig kind, the H3.6M subject and the views a rig allows (the counts' ranges are the fields')."""
        if self.rig not in RIG_KINDS:
            raise ValueError(f"SceneConfig.rig={self.rig!r} is unknown; allowed: {list(RIG_KINDS)}")
        if self.rig == "h36m" and self.num_views > 4:
            raise ValueError(f"SceneConfig.num_views={self.num_views} is out of range for rig 'h36m'; allowed: [2, 4]")
        subjects = {f"S{i}" for i in range(1, 12)}
        if self.h36m_subject not in subjects:
            raise ValueError(f"SceneConfig.h36m_subject={self.h36m_subject!r} is unknown; allowed: S1 .. S11")

    def _checked_layout(self) -> dict[str, object]:
        """Check where the cameras stand, the absences, the people's heights, the detector and the behaviour; the
        normalised (min, max) ranges by field name."""
        cam_h = ordered_pair(_OWNER, "camera_height_range_m", self.camera_height_range_m, 0.3, 10.0)
        elevation = ordered_pair(_OWNER, "dome_elevation_range_deg", self.dome_elevation_range_deg, -20.0, 80.0)
        if self.far_views > self.num_views - 1:
            raise ValueError(f"SceneConfig.far_views must be {Range(0, self.num_views - 1, integer=True).describe()} "
                             f"(one view at least is not far), got {self.far_views}")
        if self.far_views and self.rig == "h36m":
            raise ValueError("SceneConfig.far_views must be 0 for rig 'h36m' (its cameras are measured ones)")
        far = ordered_pair(_OWNER, "far_distance_factor", self.far_distance_factor, 1.2, 6.0)
        heights = ordered_pair(_OWNER, "height_range_m", self.height_range_m, 1.4, 2.0)
        if not isinstance(self.noise, DetectorNoise):
            raise ValueError(f"SceneConfig.noise must be a DetectorNoise, got {type(self.noise).__name__}")
        if self.behaviour not in BEHAVIOURS:
            raise ValueError(f"SceneConfig.behaviour={self.behaviour!r} is unknown; allowed: {list(BEHAVIOURS)}")
        return {"camera_height_range_m": cam_h, "dome_elevation_range_deg": elevation, "far_distance_factor": far,
                "height_range_m": heights}

    def _checked_lenses(self, focal: tuple[float, float], size: tuple[int, int]) -> dict[str, object]:
        """Check the lenses (distortion, focal aspect, principal point, field of view) and the camera tilt, given the
        checked focal range (pixels) and image size (pixels); the normalised values by field name."""
        k1 = ordered_pair(_OWNER, "distortion_k1_range", self.distortion_k1_range, *K1_LIMITS)
        pitch = self.camera_pitch_range_deg
        if pitch is not None:
            pitch = ordered_pair(_OWNER, "camera_pitch_range_deg", pitch, *PITCH_LIMITS_DEG)
        k2 = ordered_pair(_OWNER, "distortion_k2_range", self.distortion_k2_range, *K2_LIMITS)
        aspect = ordered_pair(_OWNER, "focal_aspect_range", self.focal_aspect_range, *FOCAL_ASPECT_LIMITS)
        if self.principal_point_offset_max_frac and self.principal_point_offset_px:
            raise ValueError("SceneConfig.principal_point_offset_max_frac and principal_point_offset_px are both set; "
                             "allowed: one of them (the other 0)")
        fov = self.horizontal_fov_range_deg
        if fov is not None:
            fov = ordered_pair(_OWNER, "horizontal_fov_range_deg", fov, *FOV_LIMITS_DEG)
            if self.rig == "h36m":
                raise ValueError("SceneConfig.horizontal_fov_range_deg must be None for rig 'h36m' (its focal lengths "
                                 "are measured ones)")
        _check_lens(k1, k2, aspect, focal, fov, size)
        return {"distortion_k1_range": k1, "camera_pitch_range_deg": pitch, "distortion_k2_range": k2,
                "focal_aspect_range": aspect,
                "principal_point_offset_max_frac": float(self.principal_point_offset_max_frac),
                "horizontal_fov_range_deg": fov}

    def _checked_clocks(self) -> dict[str, object]:
        """Check the views' clocks (time offsets, seconds; frame rates, frames per second); the normalised values by
        field name."""
        offsets = ordered_pair(_OWNER, "time_offset_range_s", self.time_offset_range_s, *TIME_OFFSET_LIMITS_S)
        choices = self.view_fps_choices
        if choices is not None:
            if not (isinstance(choices, (tuple, list)) and 1 <= len(choices) <= 8):
                raise ValueError(f"SceneConfig.view_fps_choices={choices!r} must be None or 1 to 8 frame rates in "
                                 f"[{VIEW_FPS_LIMITS[0]}, {VIEW_FPS_LIMITS[1]}]")
            rate = Range(*VIEW_FPS_LIMITS)
            for value in choices:
                if not rate.admits(value):
                    raise ValueError(f"SceneConfig.view_fps_choices: each must be {rate.describe()}, got {value!r}")
            choices = tuple(float(v) for v in choices)
        return {"time_offset_range_s": offsets, "view_fps_choices": choices}

    @property
    def duration_s(self) -> float:
        """Length of the scene, seconds."""
        return self.num_frames / self.fps

    @property
    def unsynced(self) -> bool:
        """Whether the views film on their own clocks (time offsets or per-view frame rates asked for)."""
        return self.time_offset_range_s != (0.0, 0.0) or self.view_fps_choices is not None



def _checked_image_size(size: object) -> tuple[int, int]:
    """Check ``SceneConfig.image_size_px``: integer (width, height), pixels, each side within
    ``IMAGE_SIZE_LIMITS_PX``; returns it as a tuple of ints."""
    (w_lo, h_lo), (w_hi, h_hi) = IMAGE_SIZE_LIMITS_PX
    if not (
        isinstance(size, (tuple, list))
        and len(size) == 2
        and all(isinstance(v, int) and not isinstance(v, bool) for v in size)
        and w_lo <= size[0] <= w_hi
        and h_lo <= size[1] <= h_hi
    ):
        raise ValueError(
            f"SceneConfig.image_size_px={size!r} is out of range; allowed: integer (width, height), "
            f"each side in [{w_lo}, {w_hi}] (e.g. (1920, 1080) or (1080, 1920))"
        )
    return int(size[0]), int(size[1])


def _checked_area(area: object, num_people: int) -> tuple[float, float]:
    """Check ``SceneConfig.area_size_m``: (x, y), metres, each side in [2, 30] and large enough for ``num_people``
    people; returns it as a tuple of floats."""
    if not (
        isinstance(area, (tuple, list))
        and len(area) == 2
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) and 2.0 <= v <= 30.0 for v in area)
    ):
        raise ValueError(f"SceneConfig.area_size_m={area!r} is out of range; allowed: (x, y) each in [2, 30] m")
    min_area = max(4.0, _AREA_PER_PERSON_M2 * num_people)
    if area[0] * area[1] < min_area:
        raise ValueError(
            f"SceneConfig.area_size_m={area!r} is too small for {num_people} people; "
            f"allowed: an area of at least {min_area:.1f} m^2"
        )
    return float(area[0]), float(area[1])


def _check_lens(k1: tuple[float, float], k2: tuple[float, float], aspect: tuple[float, float],
                focal_px: tuple[float, float], fov_deg: tuple[float, float] | None, size: tuple[int, int]) -> None:
    """With a k2 or a field of view asked for, the lens of the smallest coefficients (the first to fold: the model's
    slope grows with every coefficient) must be one-to-one over the whole image at the shortest focal or the widest
    field of view; a field of view must lie inside the fold of that lens."""
    if k2 == (0.0, 0.0) and fov_deg is None:
        return  # k1-only lenses keep their old rule: joints beyond a fold inside the image are not seen
    width, height = size
    corner_over_half_width = math.hypot(1.0, height / (width * aspect[0]))
    if fov_deg is None:
        half_width = width / (2.0 * focal_px[0])
    else:
        half_fov_tan = math.tan(math.radians(fov_deg[1]) / 2.0)
        fold = fold_radius(k1[0], k2[0])
        if half_fov_tan >= fold:
            raise ValueError(
                f"SceneConfig.horizontal_fov_range_deg={fov_deg!r} is out of range for the lens k1={k1[0]}, k2={k2[0]}: "
                f"it folds at {math.degrees(2.0 * math.atan(fold)):.1f} degrees; allowed: a widest field of view "
                "below that, or larger k1 / k2")
        half_width = float(distorted_radius(half_fov_tan, k1[0], k2[0]))
    corner = half_width * corner_over_half_width
    if not fits_monotonic(k1[0], k2[0], corner):
        raise ValueError(
            f"SceneConfig.distortion_k2_range={k2!r} with distortion_k1_range={k1!r} folds inside the image (lens k1="
            f"{k1[0]}, k2={k2[0]} at the image corner, normalised radius {corner:.2f}); allowed: a lens one-to-one over "
            "the image (larger k1 / k2, a longer focal or a narrower field of view)")
