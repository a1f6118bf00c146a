"""SceneConfig / DetectorNoise validation and the presets (no body model needed)."""

from __future__ import annotations

import pytest

from humancal.synthetic import PRESETS, DetectorNoise, SceneConfig, preset, preset_names


@pytest.mark.parametrize(
    ("changes", "field", "allowed"),
    [
        ({"num_people": -1}, "num_people", "[1, 8]"),
        ({"num_people": 0}, "num_people", "[1, 8]"),
        ({"num_people": 9}, "num_people", "[1, 8]"),
        ({"num_people": 2.0}, "num_people", "integer"),
        ({"num_views": 0}, "num_views", "[2, 31]"),
        ({"num_views": 1}, "num_views", "[2, 31]"),
        ({"num_views": 32}, "num_views", "[2, 31]"),
        ({"num_views": -3}, "num_views", "[2, 31]"),
        ({"num_frames": 0}, "num_frames", "[1, "),
        ({"num_frames": -5}, "num_frames", "[1, "),
        ({"fps": 0.0}, "fps", "[1, 1000]"),
        ({"seed": -1}, "seed", "[0, "),
        ({"rig": "hemisphere"}, "rig", "'ring', 'arc', 'dome', 'h36m'"),
        ({"far_views": 5}, "far_views", "[0, 4]"),
        ({"far_views": 1, "rig": "h36m", "num_views": 4}, "far_views", "must be 0 for rig 'h36m'"),
        ({"dome_elevation_range_deg": (-30.0, 10.0)}, "dome_elevation_range_deg", "[-20.0, 80.0]"),
        ({"rig": "h36m", "num_views": 5}, "num_views", "[2, 4]"),
        ({"h36m_subject": "S12"}, "h36m_subject", "S1 .. S11"),
        ({"focal_range_px": (400.0, 1000.0)}, "focal_range_px", "[500.0, 2500.0]"),
        ({"focal_range_px": (1000.0, 3000.0)}, "focal_range_px", "[500.0, 2500.0]"),
        ({"focal_range_px": (1500.0, 1000.0)}, "focal_range_px", "min <= max"),
        ({"focal_range_px": 1000.0}, "focal_range_px", "(min, max)"),
        ({"image_size_px": (320, 240)}, "image_size_px", "each side in [480, 1920]"),
        ({"image_size_px": (3840, 2160)}, "image_size_px", "each side in [480, 1920]"),
        ({"image_size_px": (1080, 2160)}, "image_size_px", "each side in [480, 1920]"),
        ({"image_size_px": (1280.0, 720.0)}, "image_size_px", "integer"),
        ({"area_size_m": (1.0, 5.0)}, "area_size_m", "[2, 30]"),
        ({"num_people": 8, "area_size_m": (3.0, 3.0)}, "area_size_m", "at least 16.0 m^2"),
        ({"camera_height_range_m": (-1.0, 2.0)}, "camera_height_range_m", "[0.3, 10.0]"),
        ({"area_fill": 2.0}, "area_fill", "[0.3, 1.2]"),
        ({"arc_span_deg": 360.0}, "arc_span_deg", "[30, 330]"),
        ({"height_range_m": (1.2, 1.9)}, "height_range_m", "[1.4, 2.0]"),
        ({"noise": {"jitter_std_frac": 0.1}}, "noise", "DetectorNoise"),
        ({"behaviour": "dancing"}, "behaviour", "'mixed', 'seated', 'low'"),
        ({"distortion_k1_range": (-0.6, 0.0)}, "distortion_k1_range", "[-0.5, 0.5]"),
        ({"distortion_k1_range": (0.2, 0.1)}, "distortion_k1_range", "min <= max"),
        ({"distortion_k1_range": 0.1}, "distortion_k1_range", "(min, max)"),
        ({"camera_pitch_range_deg": (-5.0, 30.0)}, "camera_pitch_range_deg", "[0.0, 75.0]"),
        ({"camera_pitch_range_deg": (50.0, 80.0)}, "camera_pitch_range_deg", "[0.0, 75.0]"),
        ({"camera_pitch_range_deg": 60.0}, "camera_pitch_range_deg", "(min, max)"),
    ],
)
def test_scene_config_rejects_bad_values_with_a_one_line_message(changes, field, allowed):
    with pytest.raises(ValueError) as info:
        SceneConfig(**changes)
    message = str(info.value)
    assert f"SceneConfig.{field}" in message or (field == "noise" and "SceneConfig.noise" in message)
    assert allowed in message
    assert "\n" not in message


@pytest.mark.parametrize(
    ("changes", "field"),
    [
        ({"flip_rate": 1.5}, "flip_rate"),
        ({"person_miss_rate": -0.1}, "person_miss_rate"),
        ({"jitter_std_frac": -0.01}, "jitter_std_frac"),
        ({"occluded_jitter_factor": 0.5}, "occluded_jitter_factor"),
        ({"min_visible_joints": 0}, "min_visible_joints"),
        ({"min_visible_joints": 24}, "min_visible_joints"),
        ({"false_positives_per_image": -1.0}, "false_positives_per_image"),
        ({"score_mean": float("nan")}, "score_mean"),
    ],
)
def test_detector_noise_rejects_bad_values(changes, field):
    with pytest.raises(ValueError, match=rf"DetectorNoise\.{field} must be"):
        DetectorNoise(**changes)


def test_config_defaults_are_valid_and_hashable():
    config = SceneConfig()
    assert (config.num_people, config.num_views, config.fps) == (4, 5, 30.0)
    assert config == SceneConfig(focal_range_px=[900, 1600], image_size_px=[1920, 1080])  # lists normalised
    assert hash(config) == hash(SceneConfig())
    assert config.duration_s == pytest.approx(10.0)


def test_replace_validates_and_names_unknown_fields():
    config = SceneConfig()
    assert config.replace(seed=7).seed == 7
    with pytest.raises(ValueError, match="num_views"):
        config.replace(num_views=1)
    with pytest.raises(ValueError, match=r"no field\(s\) \['num_cameras'\]"):
        config.replace(num_cameras=3)


def test_detector_noise_none_is_perfect():
    clean = DetectorNoise.none()
    assert clean.jitter_std_frac == 0.0 and clean.flip_rate == 0.0 and clean.false_positives_per_image == 0.0
    assert clean.person_miss_rate == 0.0 and clean.joint_miss_rate == 0.0 and clean.score_mean == 1.0


def test_presets_demo_and_tiny():
    demo, tiny = preset("demo"), preset("tiny")
    assert (demo.num_people, demo.num_views, demo.num_frames, demo.rig) == (4, 5, 300, "ring")
    assert demo.noise == DetectorNoise()
    assert (tiny.num_people, tiny.num_views, tiny.num_frames) == (2, 3, 20)
    assert {"demo", "tiny"} <= set(preset_names())
    assert all(isinstance(config, SceneConfig) for config in PRESETS.values())


def test_preset_overrides_and_unknown_name():
    config = preset("demo", seed=3, num_frames=60)
    assert (config.seed, config.num_frames, config.num_people) == (3, 60, 4)
    assert preset("demo").seed == 0  # the registry is not modified
    with pytest.raises(ValueError, match=r"unknown synthetic preset 'demoo'; known presets: \["):
        preset("demoo")
    with pytest.raises(ValueError, match="num_views"):
        preset("tiny", num_views=40)


def test_new_fields_default_to_todays_scenes_and_accept_the_documented_values():
    config = SceneConfig()
    assert config.behaviour == "mixed"
    assert config.distortion_k1_range == (0.0, 0.0)
    assert config.camera_pitch_range_deg is None
    for behaviour in ("mixed", "seated", "low"):
        assert SceneConfig(behaviour=behaviour).behaviour == behaviour
    assert SceneConfig(image_size_px=(1080, 1920)).image_size_px == (1080, 1920)
    assert SceneConfig(image_size_px=(480, 480)).image_size_px == (480, 480)
    portrait_lens = SceneConfig(
        image_size_px=[720, 1280], distortion_k1_range=[-0.3, 0], camera_pitch_range_deg=[50, 70]
    )
    assert portrait_lens.distortion_k1_range == (-0.3, 0.0)  # lists normalised to tuples of floats
    assert portrait_lens.camera_pitch_range_deg == (50.0, 70.0)
    assert hash(portrait_lens) == hash(portrait_lens.replace())
