"""Random activity schedules (walk, turn, stand, gesture, crouch, sit, bend) and their smooth per-frame
envelopes, for each scene behaviour (``SceneConfig.behaviour``)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

__all__ = [
    "ACTIVITIES",
    "ACTIVITY_PROBABILITIES",
    "GESTURES",
    "Segment",
    "ActivityTrack",
    "plan_activities",
    "activity_track",
    "smooth",
]

ACTIVITIES: tuple[str, ...] = ("walk", "turn", "stand", "gesture", "crouch", "sit", "bend")
"""Activity kinds; the index is the code stored per frame (new kinds are appended, so codes keep their
meaning)."""
GESTURES: tuple[str, ...] = ("wave_left", "wave_right", "raise_both", "point_left", "point_right")

_PROBABILITIES = {"walk": 0.4, "turn": 0.12, "stand": 0.16, "gesture": 0.17, "crouch": 0.15}
_LOW_PROBABILITIES = {"sit": 0.3, "crouch": 0.25, "bend": 0.2, "walk": 0.15, "stand": 0.1}
ACTIVITY_PROBABILITIES: dict[str, dict[str, float]] = {
    "mixed": _PROBABILITIES,
    "seated": {"sit": 1.0},
    "low": _LOW_PROBABILITIES,
}
"""Probability of each activity when a new one is drawn, per scene behaviour (the one just done is left out
and the rest renormalised). ``"seated"`` is one sit over the whole capture."""
_WALK_DURATION_S = {"mixed": (3.0, 8.0), "low": (1.5, 4.0)}
"""Walks are short between the low activities."""
_TRANSITION_S = 0.6
"""Width of the smoothing window between activities, seconds."""


@dataclass(frozen=True)
class Segment:
    """One activity over a frame range.

    Attributes:
        kind: one of :data:`ACTIVITIES`.
        start: first frame.
        stop: one past the last frame.
        speed_mps: walking speed, m/s (walk only; 0 otherwise).
        curvature_per_m: mean path curvature, 1/m, positive turning left (walk only).
        turn_rate_rad_s: yaw rate, rad/s, positive turning left (turn only).
        gesture: index into :data:`GESTURES` (gesture only; -1 otherwise).
        depth: crouch depth in [0, 1] (crouch), or bend depth in [0.6, 1] (bend: the trunk bends forward
            ``100 * depth`` degrees at the hips); 0 otherwise.
    """

    kind: str
    start: int
    stop: int
    speed_mps: float = 0.0
    curvature_per_m: float = 0.0
    turn_rate_rad_s: float = 0.0
    gesture: int = -1
    depth: float = 0.0


def _draw_segment(
    kind: str, start: int, fps: float, rng: np.random.Generator, walk_duration_s: tuple[float, float] = (3.0, 8.0)
) -> Segment:
    if kind == "walk":
        duration = rng.uniform(*walk_duration_s)
        return Segment(
            kind,
            start,
            start + round(duration * fps),
            speed_mps=float(rng.uniform(1.0, 1.6)),
            curvature_per_m=float(rng.choice([-1.0, 1.0]) * rng.uniform(0.0, 0.3)),
        )
    if kind == "turn":
        angle = rng.uniform(np.pi / 2, np.pi)
        rate = rng.uniform(1.2, 2.2)
        duration = angle / rate + _TRANSITION_S
        rate *= rng.choice([-1.0, 1.0])
        return Segment(kind, start, start + round(duration * fps), turn_rate_rad_s=float(rate))
    if kind == "stand":
        return Segment(kind, start, start + round(rng.uniform(1.5, 4.0) * fps))
    if kind == "gesture":
        return Segment(
            kind, start, start + round(rng.uniform(2.0, 4.0) * fps), gesture=int(rng.integers(len(GESTURES)))
        )
    if kind == "crouch":
        return Segment(kind, start, start + round(rng.uniform(2.5, 5.0) * fps), depth=float(rng.uniform(0.5, 1.0)))
    if kind == "sit":
        return Segment(kind, start, start + round(rng.uniform(4.0, 10.0) * fps))
    if kind == "bend":
        return Segment(kind, start, start + round(rng.uniform(2.0, 4.0) * fps), depth=float(rng.uniform(0.6, 1.0)))
    raise ValueError(f"unknown activity {kind!r}; known: {list(ACTIVITIES)}")


def plan_activities(
    num_frames: int, fps: float, rng: np.random.Generator, behaviour: str = "mixed"
) -> list[Segment]:
    """A random sequence of activities covering ``num_frames`` frames (no activity twice in a row).

    Args:
        num_frames: F >= 1.
        fps: frames per second.
        rng: source of randomness.
        behaviour: ``"mixed"``, ``"seated"`` or ``"low"`` (:data:`ACTIVITY_PROBABILITIES`).

    Returns:
        Contiguous segments from frame 0; the last one is cut at ``num_frames``.

    Raises:
        ValueError: unknown behaviour.
    """
    if behaviour not in ACTIVITY_PROBABILITIES:
        raise ValueError(f"behaviour={behaviour!r} is unknown; allowed: {list(ACTIVITY_PROBABILITIES)}")
    if behaviour == "seated":
        return [Segment("sit", 0, num_frames)]
    probabilities = ACTIVITY_PROBABILITIES[behaviour]
    walk_duration_s = _WALK_DURATION_S[behaviour]
    kinds = list(probabilities)
    weights = np.array([probabilities[k] for k in kinds])
    segments: list[Segment] = []
    frame, previous = 0, None
    while frame < num_frames:
        allowed = np.array([k != previous for k in kinds], dtype=np.float64) * weights
        kind = kinds[int(rng.choice(len(kinds), p=allowed / allowed.sum()))]
        segment = _draw_segment(kind, frame, fps, rng, walk_duration_s)
        stop = min(max(segment.stop, frame + 1), num_frames)
        segments.append(replace(segment, stop=stop))
        frame, previous = stop, kind
    return segments


def smooth(values: np.ndarray, fps: float, width_s: float = _TRANSITION_S) -> np.ndarray:
    """Smooth per-frame values along the last axis with a Hann window of ``width_s`` seconds (edges held).

    Args:
        values: (..., F) array.
        fps: frames per second.
        width_s: window width, seconds.

    Returns:
        (..., F) smoothed values (a constant stays exactly constant).
    """
    values = np.asarray(values, dtype=np.float64)
    taps = max(1, int(round(width_s * fps)) | 1)
    if taps == 1 or values.shape[-1] == 1:
        return values.copy()
    window = np.hanning(taps + 2)[1:-1]
    window /= window.sum()
    half = taps // 2
    padded = np.concatenate(
        [np.repeat(values[..., :1], half, axis=-1), values, np.repeat(values[..., -1:], half, axis=-1)], axis=-1
    )
    flat = padded.reshape(-1, padded.shape[-1])
    out = np.stack([np.convolve(row, window, mode="valid") for row in flat])
    return out.reshape(values.shape)


@dataclass(frozen=True)
class ActivityTrack:
    """Per-frame activity of one person: the raw label and smooth envelopes that drive motion.

    Attributes:
        label: (F,) index into :data:`ACTIVITIES` of the scheduled activity.
        speed_mps: (F,) smoothed target walking speed, m/s.
        curvature_per_m: (F,) path curvature while walking, 1/m.
        turn_rate_rad_s: (F,) smoothed yaw rate of on-the-spot turns, rad/s.
        turn: (F,) envelope in [0, 1] of on-the-spot turning (drives stepping in place).
        gesture: (F, G) envelope in [0, 1] of each gesture of :data:`GESTURES`.
        crouch: (F,) crouch depth envelope in [0, 1].
        sit: (F,) envelope in [0, 1] of sitting (1: seated).
        bend: (F,) bend depth envelope in [0, 1] (the trunk bends forward ``100 * bend`` degrees at the hips).
    """

    label: np.ndarray
    speed_mps: np.ndarray
    curvature_per_m: np.ndarray
    turn_rate_rad_s: np.ndarray
    turn: np.ndarray
    gesture: np.ndarray
    crouch: np.ndarray
    sit: np.ndarray
    bend: np.ndarray


def activity_track(segments: list[Segment], num_frames: int, fps: float, rng: np.random.Generator) -> ActivityTrack:
    """Per-frame envelopes of a schedule, smoothed so that activities blend over about half a second.

    Args:
        segments: from :func:`plan_activities`.
        num_frames: F.
        fps: frames per second.
        rng: source of randomness (slow curvature changes within walks).

    Returns:
        The :class:`ActivityTrack`.
    """
    label = np.zeros(num_frames, dtype=np.int64)
    speed = np.zeros(num_frames)
    curvature = np.zeros(num_frames)
    turn_rate = np.zeros(num_frames)
    turn = np.zeros(num_frames)
    gesture = np.zeros((len(GESTURES), num_frames))
    crouch = np.zeros(num_frames)
    sit = np.zeros(num_frames)
    bend = np.zeros(num_frames)
    for seg in segments:
        frames = slice(seg.start, seg.stop)
        label[frames] = ACTIVITIES.index(seg.kind)
        if seg.kind == "walk":
            speed[frames] = seg.speed_mps
            # The path bends more and less along a walk: a slow sinusoid around the segment's mean curvature.
            t = np.arange(seg.stop - seg.start) / fps
            period = rng.uniform(3.0, 8.0)
            curvature[frames] = seg.curvature_per_m + 0.15 * np.sin(2 * np.pi * t / period + rng.uniform(0, 2 * np.pi))
        elif seg.kind == "turn":
            turn_rate[frames] = seg.turn_rate_rad_s
            turn[frames] = 1.0
        elif seg.kind == "gesture":
            gesture[seg.gesture, frames] = 1.0
        elif seg.kind == "crouch":
            crouch[frames] = seg.depth
        elif seg.kind == "sit":
            sit[frames] = 1.0
        elif seg.kind == "bend":
            bend[frames] = seg.depth
    return ActivityTrack(
        label=label,
        speed_mps=smooth(speed, fps),
        curvature_per_m=curvature,
        turn_rate_rad_s=smooth(turn_rate, fps),
        turn=smooth(turn, fps),
        gesture=smooth(gesture, fps).T.copy(),
        crouch=smooth(crouch, fps, width_s=1.0),
        sit=smooth(sit, fps, width_s=1.0),
        bend=smooth(bend, fps, width_s=1.0),
    )
