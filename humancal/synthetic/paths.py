"""Ground paths of all people at once: walking along curves, turning, staying inside the capture area and
out of each other's way.

A small kinematic simulation at the frame rate, vectorised over people: each person has a ground position,
a heading and a speed that follows its activity's target speed; the heading turns with the path curvature,
on-the-spot turns, a steering term away from the area's edges and one away from people ahead. A final
projection step keeps everyone inside the area and at least ``min_separation_m`` apart (people standing
still are pushed only by each other, walkers give way).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from humancal.synthetic.activities import ActivityTrack

__all__ = ["Paths", "simulate_paths", "initial_positions", "seated_paths", "SEATING_LAYOUTS"]

_SPEED_TIME_CONSTANT_S = 0.4
_MAX_YAW_RATE_RAD_S = 2.5
_EDGE_LOOKAHEAD_S = 0.8
_EDGE_GAIN = 2.5
_AVOID_RANGE_M = 1.8
_AVOID_GAIN = 1.6
SEATING_LAYOUTS: tuple[str, ...] = ("circle", "audience", "scattered")
"""How seated people face: towards the area centre (a meeting, a band), all one way (an audience), or each
its own way."""
_SEAT_SHIFT_M = 0.04
_SEAT_TURN_DEG = 8.0


@dataclass(frozen=True)
class Paths:
    """Ground trajectories of P people over F frames.

    Attributes:
        position_m: (P, F, 2) ground position (x, y) of each person's root, metres.
        heading_rad: (P, F) facing direction in the ground plane, radians from +x towards +y.
        speed_mps: (P, F) forward speed, m/s.
    """

    position_m: np.ndarray
    heading_rad: np.ndarray
    speed_mps: np.ndarray


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2 * np.pi) - np.pi


def initial_positions(
    num_people: int, half_size_m: np.ndarray, min_separation_m: float, rng: np.random.Generator
) -> np.ndarray:
    """Random starting positions inside the box ``|x| <= half_size``, pairwise at least ``min_separation_m``
    apart (rejection sampling, with the separation relaxed if the box is crowded).

    Returns:
        (P, 2) positions, metres.
    """
    separation = 2.0 * min_separation_m
    while True:
        points: list[np.ndarray] = []
        for _ in range(200 * num_people):
            candidate = rng.uniform(-half_size_m, half_size_m)
            if all(np.linalg.norm(candidate - p) >= separation for p in points):
                points.append(candidate)
                if len(points) == num_people:
                    return np.array(points)
        separation *= 0.8


def _separate(
    position: np.ndarray, mobility: np.ndarray, half_size_m: np.ndarray, min_separation_m: float
) -> np.ndarray:
    """Push overlapping people apart (a few simultaneous relaxation sweeps), then clamp into the area."""
    num_people = len(position)
    # Two people on the exact same spot separate along x, in opposite directions.
    tie_break = np.sign(np.arange(num_people)[:, None] - np.arange(num_people)[None, :])[..., None] * [1.0, 0.0]
    for _ in range(4):
        delta = position[:, None, :] - position[None, :, :]
        dist = np.linalg.norm(delta, axis=-1)
        np.fill_diagonal(dist, np.inf)
        overlap = np.clip(min_separation_m - dist, 0.0, None)
        if not overlap.any():
            break
        direction = np.where(dist[..., None] > 1e-9, delta / np.maximum(dist[..., None], 1e-9), tie_break)
        # Split each overlap in proportion to how freely each of the two moves.
        share = mobility[:, None] / np.maximum(mobility[:, None] + mobility[None, :], 1e-9)
        position = position + (overlap[..., None] * share[..., None] * direction).sum(axis=1)
        position = np.clip(position, -half_size_m, half_size_m)
    return position


def simulate_paths(
    tracks: list[ActivityTrack],
    area_size_m: tuple[float, float],
    fps: float,
    rng: np.random.Generator,
    margin_m: float = 0.4,
    min_separation_m: float = 0.7,
) -> Paths:
    """Integrate every person's ground motion over the frames.

    Args:
        tracks: one :class:`ActivityTrack` per person (all with F frames).
        area_size_m: (x, y) size of the capture area centred on the origin, metres.
        fps: frames per second.
        rng: source of randomness (start positions and headings).
        margin_m: the root stays at least this far inside the area's edges, metres.
        min_separation_m: smallest distance between two people's roots, metres.

    Returns:
        The :class:`Paths`.
    """
    num_people = len(tracks)
    num_frames = len(tracks[0].label)
    dt = 1.0 / fps
    half = np.array(area_size_m, dtype=np.float64) / 2.0 - margin_m
    # Walkers steer back well before the hard edge.
    soft_half = np.maximum(half - 0.3, 0.5 * half)

    speed_target = np.stack([t.speed_mps for t in tracks])
    curvature = np.stack([t.curvature_per_m for t in tracks])
    turn_rate = np.stack([t.turn_rate_rad_s for t in tracks])

    position = initial_positions(num_people, half, min_separation_m, rng)
    heading = rng.uniform(-np.pi, np.pi, num_people)
    speed = speed_target[:, 0].copy()

    out_position = np.empty((num_people, num_frames, 2))
    out_heading = np.empty((num_people, num_frames))
    out_speed = np.empty((num_people, num_frames))
    blend = 1.0 - np.exp(-dt / _SPEED_TIME_CONSTANT_S)
    for f in range(num_frames):
        speed += (speed_target[:, f] - speed) * blend
        forward = np.stack([np.cos(heading), np.sin(heading)], axis=1)
        yaw_rate = speed * curvature[:, f] + turn_rate[:, f]

        # Steer towards the centre when the look-ahead point leaves the soft area.
        ahead = position + forward * np.maximum(0.5, speed * _EDGE_LOOKAHEAD_S)[:, None]
        outside = np.any(np.abs(ahead) > soft_half, axis=1)
        to_centre = _wrap(np.arctan2(-position[:, 1], -position[:, 0]) - heading)
        edge_turn = np.where(outside, _EDGE_GAIN * to_centre, 0.0)
        yaw_rate = np.where(outside, edge_turn, yaw_rate)

        # Veer away from people close ahead.
        delta = position[None, :, :] - position[:, None, :]
        dist = np.linalg.norm(delta, axis=-1)
        np.fill_diagonal(dist, np.inf)
        along = np.einsum("pqd,pd->pq", delta, forward)
        side = forward[:, None, 0] * delta[..., 1] - forward[:, None, 1] * delta[..., 0]
        near = (dist < _AVOID_RANGE_M) & (along > 0.0)
        push = np.where(near, (_AVOID_RANGE_M - dist) / _AVOID_RANGE_M, 0.0)
        yaw_rate = yaw_rate - _AVOID_GAIN * (push * np.where(side >= 0.0, 1.0, -1.0)).sum(axis=1) * (speed > 0.2)

        yaw_rate = np.clip(yaw_rate, -_MAX_YAW_RATE_RAD_S, _MAX_YAW_RATE_RAD_S)
        heading = _wrap(heading + yaw_rate * dt)
        forward = np.stack([np.cos(heading), np.sin(heading)], axis=1)
        position = position + forward * (speed * dt)[:, None]
        mobility = 0.05 + speed
        position = _separate(position, mobility, half, min_separation_m)

        out_position[:, f] = position
        out_heading[:, f] = heading
        out_speed[:, f] = speed
    return Paths(position_m=out_position, heading_rad=out_heading, speed_mps=out_speed)


def _wander(
    rng: np.random.Generator, shape: tuple[int, ...], num_frames: int, fps: float, period_s: float
) -> np.ndarray:
    """Smooth random wandering in [-1, 1], shape ``shape + (F,)``: eased values every ``period_s`` seconds."""
    knots = int(np.ceil(num_frames / fps / period_s)) + 2
    values = np.clip(rng.normal(0.0, 0.6, shape + (knots,)), -1.0, 1.0)
    t = np.arange(num_frames) / (fps * period_s)
    index = np.floor(t).astype(np.int64)
    ease = 0.5 - 0.5 * np.cos(np.pi * (t - index))
    return (1.0 - ease) * values[..., index] + ease * values[..., index + 1]


def seated_paths(
    num_people: int,
    num_frames: int,
    area_size_m: tuple[float, float],
    fps: float,
    rng: np.random.Generator,
    margin_m: float = 0.8,
    min_separation_m: float = 0.8,
) -> Paths:
    """Fixed seats for everybody: spots spread over the area and facing one of :data:`SEATING_LAYOUTS`, with
    small slow shifts on the seat (a few centimetres, a few degrees).

    Args:
        num_people: P.
        num_frames: F.
        area_size_m: (x, y) size of the capture area centred on the origin, metres.
        fps: frames per second.
        rng: source of randomness.
        margin_m: the spots stay at least this far inside the area's edges (room for the chair), metres.
        min_separation_m: half the smallest distance between two spots (relaxed when the area is crowded),
            metres.

    Returns:
        The :class:`Paths` (speed 0): ``position_m`` is where the feet are, ``heading_rad`` where the person
        faces.
    """
    half = np.maximum(np.array(area_size_m, dtype=np.float64) / 2.0 - margin_m, 0.3)
    spot = initial_positions(num_people, half, min_separation_m, rng)
    layout = SEATING_LAYOUTS[int(rng.integers(len(SEATING_LAYOUTS)))]
    if layout == "circle":
        heading = np.arctan2(-spot[:, 1], -spot[:, 0]) + np.radians(rng.normal(0.0, 15.0, num_people))
    elif layout == "audience":
        heading = rng.uniform(-np.pi, np.pi) + np.radians(rng.normal(0.0, 10.0, num_people))
    else:
        heading = rng.uniform(-np.pi, np.pi, num_people)
    shift = _SEAT_SHIFT_M * _wander(rng, (num_people, 2), num_frames, fps, 6.0)
    turn = np.radians(_SEAT_TURN_DEG) * _wander(rng, (num_people,), num_frames, fps, 5.0)
    return Paths(
        position_m=spot[:, None, :] + shift.transpose(0, 2, 1),
        heading_rad=_wrap(heading[:, None] + turn),
        speed_mps=np.zeros((num_people, num_frames)),
    )
