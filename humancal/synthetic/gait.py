"""Procedural joint angles: a walking cycle, standing sway, gestures, crouching, and (from
:mod:`humancal.synthetic.postures`) sitting and bending over, blended per frame.

The walking cycle is written against the cycle fraction ``u`` in [0, 1) of each leg: the heel strikes at
``u = 0``, the foot stays on the floor until ``u = 0.6`` (toe-off) and swings forward until the next strike;
the right leg runs half a cycle behind the left. While it carries the body (to 50 %) the foot moves straight
back relative to the hip at the walking speed (the hip angle follows from the leg length), so a planted foot
hardly slides. The step length grows with speed and leg length, the cadence covers the rest; slow or standing
people take small steps or none.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from humancal.synthetic.activities import GESTURES, ActivityTrack, smooth
from humancal.synthetic.paths import Paths
from humancal.synthetic.poses import CHANNEL_INDEX, CHANNELS
from humancal.synthetic.postures import apply_bend, apply_sit, draw_seated_posture, seated_channels

__all__ = ["Style", "draw_style", "cadence_steps_per_s", "gait_channels"]


@dataclass(frozen=True)
class Style:
    """Personal motion style of one person (all angles in degrees).

    Attributes:
        arm_swing: scale of the arm swing while walking (relative to the hip swing).
        relaxed_elbow_deg: elbow bend of hanging arms.
        relaxed_arm_elev_deg: arm angle from vertical when relaxed.
        lean_deg: forward trunk lean while walking.
        step_scale: multiplies the step length (long or short strides; the cadence follows).
        sway_m: amplitude of the standing sway, metres.
    """

    arm_swing: float
    relaxed_elbow_deg: float
    relaxed_arm_elev_deg: float
    lean_deg: float
    step_scale: float
    sway_m: float


def draw_style(rng: np.random.Generator) -> Style:
    """A random :class:`Style`."""
    return Style(
        arm_swing=float(rng.uniform(0.5, 1.1)),
        relaxed_elbow_deg=float(rng.uniform(8.0, 25.0)),
        relaxed_arm_elev_deg=float(rng.uniform(6.0, 14.0)),
        lean_deg=float(rng.uniform(0.0, 6.0)),
        step_scale=float(rng.uniform(0.92, 1.08)),
        sway_m=float(rng.uniform(0.005, 0.02)),
    )


def step_length_m(speed_mps: np.ndarray, leg_length_m: float, scale: float = 1.0) -> np.ndarray:
    """Walking step length: about 0.85 leg lengths at 1.3 m/s, growing with the square root of speed, metres."""
    return scale * 0.85 * leg_length_m * np.sqrt(np.maximum(speed_mps, 0.5) / 1.3)


def cadence_steps_per_s(speed_mps: np.ndarray, leg_length_m: float, scale: float = 1.0) -> np.ndarray:
    """Steps per second that cover ``speed_mps`` with :func:`step_length_m` steps (at least the cadence of
    a 0.5 m/s walk, so that stepping in place keeps a natural rhythm)."""
    speed = np.maximum(speed_mps, 0.5)
    return speed / step_length_m(speed, leg_length_m, scale)


_STANCE = 0.5
"""Fraction of the gait cycle a foot is planted and carries the body alone or with the other foot (heel strike
to the other foot's heel strike); it then pushes off until about 60 % of the cycle."""
_ROLLOVER = 0.9
"""Part of the stance travel made by the leg swinging back (the rest: rolling from heel to toes)."""
_REFERENCE_EXCURSION_M = 0.32
"""Stance excursion of a typical 1.3 m/s walk, metres (amplitudes of the other channels scale with it)."""


def _foot_offset(u: np.ndarray, excursion_m: np.ndarray) -> np.ndarray:
    """Forward offset of a foot from the hip over the cycle fraction ``u`` (0 = heel strike), metres.

    Stance (``u < STANCE``): straight back from ``+X`` to ``-X`` at constant speed, so a planted foot does not
    slide while the pelvis moves on. Swing: back to ``+X`` fast at first and easing in before the heel strike
    (``1 - (1 - s)^2``), so that the thigh is already ahead when the knee is most bent, as in real gait.
    """
    x = np.asarray(excursion_m, dtype=np.float64)
    stance = u < _STANCE
    s = np.where(stance, u / _STANCE, (u - _STANCE) / (1.0 - _STANCE))
    swing = -x + 2.0 * x * (1.0 - (1.0 - s) ** 2)
    return np.where(stance, x * (1.0 - 2.0 * s), swing)


def _bump_fraction(u: np.ndarray, centre: float, left: float, right: float) -> np.ndarray:
    """A smooth cos^2 bump of the cycle fraction ``u`` (wrapping at 1): 1 at ``centre``, 0 beyond ``left``
    before it and ``right`` after it."""
    delta = (u - centre + 0.5) % 1.0 - 0.5
    width = np.where(delta < 0.0, left, right)
    inside = np.abs(delta) < width
    return np.where(inside, np.cos(0.5 * np.pi * delta / width) ** 2, 0.0)


def _smooth_noise(rng: np.random.Generator, num_frames: int, fps: float, period_s: float) -> np.ndarray:
    """Smooth random wandering: standard-normal values (clipped at 2) every ``period_s`` seconds, eased in
    between."""
    knots = int(np.ceil(num_frames / fps / period_s)) + 2
    values = np.clip(rng.normal(0.0, 1.0, knots), -2.0, 2.0)
    t = np.arange(num_frames) / (fps * period_s)
    index = np.floor(t).astype(np.int64)
    ease = 0.5 - 0.5 * np.cos(np.pi * (t - index))
    return (1.0 - ease) * values[index] + ease * values[index + 1]


def _put_walking(
    c: np.ndarray,
    cycles: np.ndarray,
    excursion: np.ndarray,
    g: np.ndarray,
    knee_lift: np.ndarray,
    leg_length_m: float,
    style: Style,
) -> None:
    """Write the walking cycle into the (F, C) channels ``c``, degrees: legs, arm swing, pelvis and trunk, from the
    (F,) gait cycles (left heel strike at integers), stance excursion (metres), gait scale ``g`` and knee lift
    (degrees)."""

    def put(name: str, value: np.ndarray | float) -> None:
        c[:, CHANNEL_INDEX[name]] = value

    left_cycle = cycles % 1.0
    for side, offset in (("l", 0.0), ("r", 0.5)):
        u = (cycles + offset) % 1.0
        hip = np.degrees(np.arcsin(np.clip(_foot_offset(u, excursion) / leg_length_m, -0.8, 0.8)))
        put(f"hip_flex_{side}", hip + 2.0 * g)
        swing = _bump_fraction(u, 0.72, 0.22, 0.25)
        loading = _bump_fraction(u, 0.1, 0.1, 0.1)
        put(f"knee_flex_{side}", 3.0 + knee_lift * swing + 10.0 * g * loading)
        heel_strike = _bump_fraction(u, 0.0, 0.08, 0.1)
        push_off = _bump_fraction(u, 0.57, 0.12, 0.1)
        put(f"foot_pitch_{side}", 10.0 * g * heel_strike - 25.0 * g * push_off)
        put(f"toe_ext_{side}", 30.0 * g * _bump_fraction(u, 0.55, 0.1, 0.08))
        arm = -style.arm_swing * 0.7 * hip
        put(f"shoulder_flex_{side}", arm + 3.0 * g)
        put(f"elbow_flex_{side}", style.relaxed_elbow_deg + 0.6 * np.clip(arm, 0.0, None) + 5.0 * g)
        put(f"arm_elev_{side}", style.relaxed_arm_elev_deg)
    amplitude = np.degrees(np.arcsin(np.clip(excursion / leg_length_m, 0.0, 0.8)))
    # The pelvis turns its left side forward with the left leg, the shoulders counter-rotate, and the
    # pelvis drops on the swing side during single support.
    put("pelvis_yaw", -0.25 * amplitude * np.cos(2 * np.pi * left_cycle))
    put("spine_twist", 0.35 * amplitude * np.cos(2 * np.pi * left_cycle))
    put("pelvis_roll", 3.0 * g * np.cos(4 * np.pi * left_cycle))
    put("spine_lean", style.lean_deg * np.clip(g, 0.0, 1.0))


def gait_channels(
    track: ActivityTrack,
    paths: Paths,
    person: int,
    leg_length_m: float,
    style: Style,
    fps: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Joint-angle channels of one person over all frames, and a small horizontal sway of the root.

    Args:
        track: the person's activity envelopes.
        paths: ground paths of everybody (row ``person`` is used).
        person: row of ``paths``.
        leg_length_m: hip-to-ankle length of the person, metres (sets the hip swing for a step length).
        style: the person's :class:`Style`.
        fps: frames per second.
        rng: source of randomness (sway and head motion; a seated posture and upper-body activity when the
            person sits at some point).

    Returns:
        channels: (F, C) degrees, columns ``humancal.synthetic.poses.CHANNELS``.
        sway_m: (F, 2) horizontal offset of the root in the body frame (x: body left, y: body forward), metres.
    """
    num_frames = len(track.label)
    dt = 1.0 / fps
    speed = paths.speed_mps[person]
    cadence = cadence_steps_per_s(speed, leg_length_m, style.step_scale)
    # Gait cycles (one stride = two steps); the left heel strikes at integer cycles.
    cycles = np.cumsum(0.5 * cadence * dt) + rng.uniform(0.0, 1.0)
    step = speed / cadence
    # Half the backward excursion of a planted foot relative to the pelvis: the pelvis travels 2 * STANCE steps
    # while a foot is planted, a part of it rolling from heel to toes. Turning on the spot: small steps.
    excursion = np.clip(_STANCE * step * _ROLLOVER, 0.0, 0.6 * leg_length_m) + 0.06 * track.turn
    g = np.clip(excursion / _REFERENCE_EXCURSION_M, 0.0, 1.3)
    knee_lift = 55.0 * np.clip(g, 0.0, 1.1) + 25.0 * track.turn

    c = np.zeros((num_frames, len(CHANNELS)))

    def put(name: str, value: np.ndarray | float) -> None:
        c[:, CHANNEL_INDEX[name]] = value

    left_cycle = cycles % 1.0
    _put_walking(c, cycles, excursion, g, knee_lift, leg_length_m, style)

    # Standing still is never perfectly still: slow sway, weight shifts and looking around.
    still = 1.0 - np.clip(g, 0.0, 1.0)
    shift = _smooth_noise(rng, num_frames, fps, 2.5)
    put("hip_abd_l", 2.0 * still * shift)
    put("hip_abd_r", -2.0 * still * shift)
    put("neck_yaw", (10.0 + 15.0 * still) * _smooth_noise(rng, num_frames, fps, 3.0))
    put("neck_pitch", 5.0 + 6.0 * _smooth_noise(rng, num_frames, fps, 3.0))
    sway = style.sway_m * still[:, None] * np.stack(
        [_smooth_noise(rng, num_frames, fps, 2.0), _smooth_noise(rng, num_frames, fps, 2.5)], axis=1
    )
    # Lateral weight transfer towards the stance leg while walking (left stance: 0 to 60 % of the cycle).
    sway[:, 0] += 0.02 * np.clip(g, 0.0, 1.0) * np.cos(2 * np.pi * (left_cycle - 0.3))

    c = _apply_gestures(c, track, fps)
    c = _apply_crouch(c, track.crouch)
    if track.bend.any():
        c = apply_bend(c, track.bend)
    if track.sit.any():
        c = apply_sit(c, track.sit, seated_channels(draw_seated_posture(rng), num_frames, fps, rng))
    # Round off the corners of the piecewise gait curves (toe-off, heel strike) over a tenth of a second.
    return smooth(c.T, fps, width_s=0.1).T.copy(), sway


def _gesture_arm(name: str, t: np.ndarray, wave_hz: float) -> dict[str, np.ndarray]:
    """Arm channels (one side, suffix-free) of a gesture over time ``t`` (seconds)."""
    ones = np.ones_like(t)
    if name == "wave":
        return {
            "shoulder_flex": 10.0 * ones,
            "arm_elev": 100.0 * ones,
            "arm_twist": 90.0 * ones,
            "elbow_flex": 85.0 + 25.0 * np.sin(2 * np.pi * wave_hz * t),
        }
    if name == "raise":
        return {"shoulder_flex": 15.0 * ones, "arm_elev": 160.0 * ones, "arm_twist": 0 * ones, "elbow_flex": 10 * ones}
    if name == "point":
        return {"shoulder_flex": 85.0 * ones, "arm_elev": 5.0 * ones, "arm_twist": 0 * ones, "elbow_flex": 5 * ones}
    raise ValueError(f"unknown gesture arm {name!r}")


_GESTURE_SIDES = {
    "wave_left": (("wave", "l"),),
    "wave_right": (("wave", "r"),),
    "raise_both": (("raise", "l"), ("raise", "r")),
    "point_left": (("point", "l"),),
    "point_right": (("point", "r"),),
}


def _apply_gestures(channels: np.ndarray, track: ActivityTrack, fps: float) -> np.ndarray:
    """Blend gesture arm poses over the current arms, weighted by each gesture's envelope."""
    t = np.arange(len(track.label)) / fps
    out = channels.copy()
    for g, gesture in enumerate(GESTURES):
        weight = track.gesture[:, g]
        if not weight.any():
            continue
        for arm, side in _GESTURE_SIDES[gesture]:
            for name, value in _gesture_arm(arm, t, wave_hz=1.8).items():
                col = CHANNEL_INDEX[f"{name}_{side}"]
                out[:, col] = (1.0 - weight) * out[:, col] + weight * value
        # Look at the raised hand / pointing direction a little.
        out[:, CHANNEL_INDEX["neck_pitch"]] -= 10.0 * weight
    return out


_CROUCH_POSE = {
    "hip_flex_l": 100.0,
    "hip_flex_r": 100.0,
    "hip_abd_l": 12.0,
    "hip_abd_r": 12.0,
    "knee_flex_l": 125.0,
    "knee_flex_r": 125.0,
    "foot_pitch_l": 0.0,
    "foot_pitch_r": 0.0,
    "toe_ext_l": 0.0,
    "toe_ext_r": 0.0,
    "spine_lean": 30.0,
    "shoulder_flex_l": 35.0,
    "shoulder_flex_r": 35.0,
    "elbow_flex_l": 35.0,
    "elbow_flex_r": 35.0,
    "pelvis_yaw": 0.0,
    "pelvis_roll": 0.0,
    "spine_twist": 0.0,
}
"""Full-depth crouch (depth 1); a crouch of depth d blends d of the way to it."""


def _apply_crouch(channels: np.ndarray, depth: np.ndarray) -> np.ndarray:
    out = channels.copy()
    for name, value in _CROUCH_POSE.items():
        col = CHANNEL_INDEX[name]
        out[:, col] = (1.0 - depth) * out[:, col] + depth * value
    return out
