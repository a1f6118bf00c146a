"""Named scene configurations: the embedded default dataset and small scenes for tests."""

from __future__ import annotations

from types import MappingProxyType

from humancal.synthetic.config import SceneConfig
from humancal.synthetic.detector_noise import DetectorNoise

__all__ = ["PRESETS", "preset", "preset_names"]

PRESETS: MappingProxyType[str, SceneConfig] = MappingProxyType(
    {
        # The embedded default: the paper's reference workload shape (4 people, 5 views), 10 s.
        "demo": SceneConfig(num_people=4, num_views=5, num_frames=300, rig="ring", seed=0),
        # The reference workload of the performance targets: 30 s at 30 fps.
        "benchmark": SceneConfig(num_people=4, num_views=5, num_frames=900, rig="ring", seed=1),
        # Shelf/Campus-like: fewer cameras on one side of the room.
        "arc": SceneConfig(num_people=3, num_views=3, num_frames=300, rig="arc", arc_span_deg=120.0, seed=2),
        # Crowded: the most people, many views.
        "crowd": SceneConfig(
            num_people=8, num_views=8, num_frames=300, rig="ring", area_size_m=(6.0, 6.0), seed=3
        ),
        # Small and fast, for tests.
        "tiny": SceneConfig(num_people=2, num_views=3, num_frames=20, rig="ring", seed=0),
        # Consumer rigs (docs/synthetic.md, "Consumer rigs"). Phones: portrait videos started by hand (time offsets up
        # to 2 s, 30 or 60 fps), mild lenses (|k1| <= 0.1), principal points up to 5 % off centre, fx != fy (2 %).
        "phone": SceneConfig(
            num_people=3, num_views=5, num_frames=60, rig="ring", seed=6, image_size_px=(1080, 1920),
            focal_range_px=(1350.0, 1650.0), area_size_m=(4.0, 3.5), camera_height_range_m=(1.0, 1.8),
            distortion_k1_range=(-0.1, 0.1), principal_point_offset_max_frac=0.05, focal_aspect_range=(0.98, 1.02),
            time_offset_range_s=(-2.0, 2.0), view_fps_choices=(30.0, 60.0),
        ),
        # Action cameras: strong barrel lenses (k1 -0.3 +- 0.05, k2 0.1 +- 0.03), 100-120 degrees across the image.
        "action_cam": SceneConfig(
            num_people=3, num_views=4, num_frames=60, rig="ring", seed=7, distortion_k1_range=(-0.35, -0.25),
            distortion_k2_range=(0.07, 0.13), horizontal_fov_range_deg=(100.0, 120.0), camera_height_range_m=(1.5, 3.0),
            area_fill=1.0,
        ),
        # The same as tiny with a perfect detector (exact projections, nothing missed).
        "tiny_clean": SceneConfig(
            num_people=2, num_views=3, num_frames=20, rig="ring", seed=0, noise=DetectorNoise.none()
        ),
    }
)
"""Named configurations (read-only). ``h36m`` is not a preset because it needs the external data root; use
``preset("demo", rig="h36m", num_views=4)``."""


def preset_names() -> tuple[str, ...]:
    """Names of the presets, sorted."""
    return tuple(sorted(PRESETS))


def preset(name: str, **overrides: object) -> SceneConfig:
    """A named configuration, optionally with some fields changed.

    Args:
        name: one of :func:`preset_names`.
        **overrides: ``SceneConfig`` fields to change (validated), e.g. ``seed=3, num_frames=60``.

    Returns:
        The :class:`SceneConfig`.

    Raises:
        ValueError: unknown preset name (listing the known ones), unknown field, or invalid value.
    """
    if name not in PRESETS:
        raise ValueError(f"unknown synthetic preset {name!r}; known presets: {list(preset_names())}")
    config = PRESETS[name]
    return config.replace(**overrides) if overrides else config
