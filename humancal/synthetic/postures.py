"""Postures off the feet: sitting on an invisible chair (with upper-body activity) and bending over.

Both are joint-angle channels (``humancal.synthetic.poses.CHANNELS``) blended over the walking and standing
channels by a per-frame envelope, like the crouch of :mod:`humancal.synthetic.gait`.

Sitting: hips and knees flexed 80-100 degrees (thighs about horizontal, shanks about vertical), feet flat,
knees a little apart. There is no chair in the body model: after forward kinematics the lowest foot point is
put on the floor (:mod:`humancal.synthetic.motions`), which sets the seat height from the person's own legs.
While seated the upper body keeps busy: the trunk leans (-10 to +30 degrees, partly at the pelvis with the
thighs kept in place) and twists, the head turns and nods, and the arms go through a schedule of seated
activities: playing an instrument (forearms forward, periodic bowing or drumming), talking with the hands,
hands on the knees, hands in the lap, and gestures (wave, point, raise a hand).

Bending over: the trunk bends forward at the hips (pelvis tilt and spine together, ``100 * depth`` degrees)
with nearly straight legs and the arms reaching down, as when picking something up.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from humancal.synthetic.activities import smooth
from humancal.synthetic.poses import CHANNEL_INDEX

__all__ = ["SeatedPosture", "SEATED_ARM_ACTIVITIES", "draw_seated_posture", "seated_channels", "apply_sit",
           "apply_bend", "LEAN_RANGE_DEG"]

SEATED_ARM_ACTIVITIES: tuple[str, ...] = ("instrument", "talk", "knees", "lap", "gesture")
"""What the arms of a seated person do, in turn."""
_ARM_PROBABILITIES = np.array([0.3, 0.15, 0.2, 0.2, 0.15])
_ARM_SEGMENT_S = (3.0, 8.0)
LEAN_RANGE_DEG = (-10.0, 30.0)
"""Forward lean of a seated trunk, degrees (negative: leaning back)."""
_PELVIS_SHARE = 0.4
"""Part of a seated lean made by tilting the pelvis (the rest by the spine)."""
_ARM_NAMES = ("shoulder_flex", "arm_elev", "arm_twist", "elbow_flex")


@dataclass(frozen=True)
class SeatedPosture:
    """How one person sits (angles in degrees).

    Attributes:
        hip_flex_deg: (2,) hip flexion, left and right, in [80, 100] (90: thighs horizontal).
        knee_flex_deg: (2,) knee flexion, left and right, in [80, 100] (90: shanks vertical).
        hip_abd_deg: knees apart: abduction of each thigh, in [3, 15].
        lean_deg: the person's mean forward lean of the trunk, in [0, 12].
        instrument: ``"bow"`` (one arm bowing, the other fingering) or ``"drum"`` (both forearms beating).
        tempo_hz: frequency of the instrument's periodic motion.
    """

    hip_flex_deg: np.ndarray
    knee_flex_deg: np.ndarray
    hip_abd_deg: float
    lean_deg: float
    instrument: str
    tempo_hz: float


def draw_seated_posture(rng: np.random.Generator) -> SeatedPosture:
    """A random :class:`SeatedPosture`."""
    hip = rng.uniform(83.0, 97.0) + rng.uniform(-3.0, 3.0, 2)
    return SeatedPosture(
        hip_flex_deg=hip,
        knee_flex_deg=rng.uniform(80.0, 100.0, 2),
        hip_abd_deg=float(rng.uniform(3.0, 15.0)),
        lean_deg=float(rng.uniform(0.0, 12.0)),
        instrument=str(rng.choice(["bow", "drum"])),
        tempo_hz=float(rng.uniform(0.6, 2.0)),
    )


def _wander(rng: np.random.Generator, num_frames: int, fps: float, period_s: float) -> np.ndarray:
    """Smooth random wandering in about [-1, 1]: eased values drawn every ``period_s`` seconds."""
    knots = int(np.ceil(num_frames / fps / period_s)) + 2
    values = np.clip(rng.normal(0.0, 0.6, knots), -1.0, 1.0)
    t = np.arange(num_frames) / (fps * period_s)
    index = np.floor(t).astype(np.int64)
    ease = 0.5 - 0.5 * np.cos(np.pi * (t - index))
    return (1.0 - ease) * values[index] + ease * values[index + 1]


def _arm_schedule(num_frames: int, fps: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame weights (F, A) of :data:`SEATED_ARM_ACTIVITIES` (one at a time, blended over 0.6 s) and the
    gesture of each frame (F,): 0 wave, 1 point, 2 raise; side 0 left, 1 right (packed as 2 * kind + side)."""
    weights = np.zeros((len(SEATED_ARM_ACTIVITIES), num_frames))
    gesture = np.zeros(num_frames, dtype=np.int64)
    frame, previous = 0, -1
    while frame < num_frames:
        allowed = _ARM_PROBABILITIES * (np.arange(len(SEATED_ARM_ACTIVITIES)) != previous)
        kind = int(rng.choice(len(SEATED_ARM_ACTIVITIES), p=allowed / allowed.sum()))
        stop = min(num_frames, frame + max(1, round(rng.uniform(*_ARM_SEGMENT_S) * fps)))
        weights[kind, frame:stop] = 1.0
        gesture[frame:stop] = int(rng.integers(6))
        frame, previous = stop, kind
    return smooth(weights, fps).T.copy(), gesture


def _instrument_arms(posture: SeatedPosture, t: np.ndarray, side: int) -> dict[str, np.ndarray]:
    phase = 2.0 * np.pi * posture.tempo_hz * t
    ones = np.ones_like(t)
    if posture.instrument == "drum":
        beat = np.sin(phase + np.pi * side)
        return {"shoulder_flex": 30.0 + 6.0 * beat, "arm_elev": 20.0 * ones, "arm_twist": 10.0 * ones,
                "elbow_flex": 85.0 + 15.0 * beat}
    if side == 1:  # the bowing arm
        return {"shoulder_flex": 30.0 + 10.0 * np.sin(phase), "arm_elev": 35.0 + 12.0 * np.sin(phase),
                "arm_twist": 15.0 * ones, "elbow_flex": 90.0 + 25.0 * np.sin(phase + 0.5)}
    return {"shoulder_flex": 40.0 * ones, "arm_elev": 30.0 * ones, "arm_twist": 20.0 * ones,
            "elbow_flex": 110.0 + 5.0 * np.sin(3.0 * phase)}


def _gesture_arms(gesture: np.ndarray, t: np.ndarray, side: int) -> dict[str, np.ndarray]:
    kind, gesturing = gesture // 2, (gesture % 2) == side
    wave = {"shoulder_flex": 10.0, "arm_elev": 100.0, "arm_twist": 90.0, "elbow_flex": 85.0}
    point = {"shoulder_flex": 85.0, "arm_elev": 5.0, "arm_twist": 0.0, "elbow_flex": 5.0}
    raised = {"shoulder_flex": 15.0, "arm_elev": 160.0, "arm_twist": 0.0, "elbow_flex": 10.0}
    lap = {"shoulder_flex": 15.0, "arm_elev": 10.0, "arm_twist": 0.0, "elbow_flex": 70.0}
    out = {}
    for name in _ARM_NAMES:
        value = np.choose(np.minimum(kind, 2), [wave[name], point[name], raised[name]]).astype(np.float64)
        if name == "elbow_flex":
            value = value + np.where(kind == 0, 25.0 * np.sin(2.0 * np.pi * 1.8 * t), 0.0)
        out[name] = np.where(gesturing, value, lap[name])
    return out


def seated_channels(
    posture: SeatedPosture, num_frames: int, fps: float, rng: np.random.Generator
) -> dict[str, np.ndarray]:
    """Channels of a seated person over all frames: legs from ``posture``, trunk, head and arms moving.

    Args:
        posture: how the person sits.
        num_frames: F.
        fps: frames per second.
        rng: source of randomness (lean, twist, head motion, arm schedule).

    Returns:
        Channel name -> (F,) degrees, for every channel a seated pose sets.
    """
    t = np.arange(num_frames) / fps
    weights, gesture = _arm_schedule(num_frames, fps, rng)
    knees = weights[:, SEATED_ARM_ACTIVITIES.index("knees")]
    instrument = weights[:, SEATED_ARM_ACTIVITIES.index("instrument")]
    talk = weights[:, SEATED_ARM_ACTIVITIES.index("talk")]
    # Hands on the knees need a forward lean; playing, a slight one.
    lean = posture.lean_deg + 12.0 * _wander(rng, num_frames, fps, 3.0) + 15.0 * knees + 4.0 * instrument
    lean = np.clip(lean, *LEAN_RANGE_DEG)
    pelvis = _PELVIS_SHARE * lean
    out: dict[str, np.ndarray] = {
        "pelvis_pitch": pelvis,
        "spine_lean": lean - pelvis,
        "spine_twist": 15.0 * _wander(rng, num_frames, fps, 3.0),
        "spine_side": 4.0 * _wander(rng, num_frames, fps, 5.0),
        "neck_yaw": 40.0 * _wander(rng, num_frames, fps, 2.5),
        # Nodding while talking, otherwise looking about.
        "neck_pitch": 8.0 + 10.0 * _wander(rng, num_frames, fps, 3.0)
        + 6.0 * talk * np.sin(2.0 * np.pi * 1.2 * t),
        "pelvis_yaw": np.zeros(num_frames),
        "pelvis_roll": np.zeros(num_frames),
    }
    for i, side in enumerate(("l", "r")):
        # The pelvis tilt would lift the thighs; the hips flex the same amount more to keep them level.
        out[f"hip_flex_{side}"] = posture.hip_flex_deg[i] + pelvis
        out[f"knee_flex_{side}"] = np.full(num_frames, posture.knee_flex_deg[i])
        out[f"hip_abd_{side}"] = np.full(num_frames, posture.hip_abd_deg)
        out[f"foot_pitch_{side}"] = np.zeros(num_frames)
        out[f"toe_ext_{side}"] = np.zeros(num_frames)
        free = 0.5 + 0.5 * _wander(rng, num_frames, fps, 2.0)
        per_activity = {
            "instrument": _instrument_arms(posture, t, i),
            "talk": {"shoulder_flex": 25.0 + 12.0 * free, "arm_elev": 15.0 + 5.0 * free,
                     "arm_twist": 10.0 + 0.0 * t, "elbow_flex": 90.0 + 25.0 * free},
            "knees": {"shoulder_flex": 50.0 + 0.0 * t, "arm_elev": 12.0 + 0.0 * t, "arm_twist": 0.0 * t,
                      "elbow_flex": 15.0 + 0.0 * t},
            "lap": {"shoulder_flex": 15.0 + 0.0 * t, "arm_elev": 10.0 + 0.0 * t, "arm_twist": 0.0 * t,
                    "elbow_flex": 70.0 + 0.0 * t},
            "gesture": _gesture_arms(gesture, t, i),
        }
        for name in _ARM_NAMES:
            out[f"{name}_{side}"] = sum(
                weights[:, a] * per_activity[kind][name] for a, kind in enumerate(SEATED_ARM_ACTIVITIES)
            )
    return out


def _blend(channels: np.ndarray, weight: np.ndarray, pose: dict[str, np.ndarray | float]) -> np.ndarray:
    out = channels.copy()
    for name, value in pose.items():
        col = CHANNEL_INDEX[name]
        out[:, col] = (1.0 - weight) * out[:, col] + weight * value
    return out


def apply_sit(channels: np.ndarray, sit: np.ndarray, seated: dict[str, np.ndarray]) -> np.ndarray:
    """Blend the seated channels over ``channels`` (F, C) with the sitting envelope ``sit`` (F,) in [0, 1]."""
    return _blend(channels, sit, seated)


_BEND_POSE = {
    # The shoulders follow the pelvis and spine rotations only in part (the upper spine and the clavicles
    # stay as they are): 70 + 60 degrees of rotation bend the hip-to-shoulder line by about 100 degrees.
    "pelvis_pitch": 70.0,
    "spine_lean": 60.0,
    # The pelvis tilt turns the thighs forward 70 degrees; 60 of hip flexion leaves them 10 degrees back, so
    # the hips go back over the heels while the trunk goes forward.
    "hip_flex_l": 60.0,
    "hip_flex_r": 60.0,
    "hip_abd_l": 5.0,
    "hip_abd_r": 5.0,
    "knee_flex_l": 8.0,
    "knee_flex_r": 8.0,
    "foot_pitch_l": 0.0,
    "foot_pitch_r": 0.0,
    "toe_ext_l": 0.0,
    "toe_ext_r": 0.0,
    # Arms reach down towards the floor, the head looks at it.
    "shoulder_flex_l": 75.0,
    "shoulder_flex_r": 75.0,
    "arm_elev_l": 10.0,
    "arm_elev_r": 10.0,
    "elbow_flex_l": 15.0,
    "elbow_flex_r": 15.0,
    "neck_pitch": -20.0,
    "pelvis_yaw": 0.0,
    "pelvis_roll": 0.0,
    "spine_twist": 0.0,
}
"""Full-depth bend (depth 1: trunk 100 degrees forward at the hips); a bend of depth d blends d of the way."""


def apply_bend(channels: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """Blend the bending-over pose over ``channels`` (F, C) with the bend depth envelope ``depth`` (F,)."""
    return _blend(channels, depth, _BEND_POSE)
