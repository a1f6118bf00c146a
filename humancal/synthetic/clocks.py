"""Clocks of unsynchronised cameras: per-view frame rates and time offsets, the times of each view's frames on the
scene's reference clock, and the people's keypoints at those times.

Convention (``docs/conventions.md``, "Time"): view ``v``'s frame ``n`` is taken at reference time
``t = n / fps_v + offset_v`` seconds, so ``offset_v`` is the reference time of the view's frame 0. The reference
clock is the scene's: ``SceneConfig.fps``, its frame 0 at ``t = 0``; view 0 defines it (offset 0). The ground truth
(poses, motions) stays on the reference clock; the detections of view ``v`` carry its own frame numbers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from humancal.synthetic.config import SceneConfig

__all__ = ["ViewClocks", "draw_clocks", "synced_clocks", "keypoints_at", "hidden_at", "started_by_hand",
           "to_reference_frames"]

_EPS_FRAMES = 1e-9
"""Slack, in reference frames, when a view's frame time falls on a reference frame up to round-off."""


@dataclass(frozen=True)
class ViewClocks:
    """Every view's clock and the frames it films.

    Attributes:
        fps: (V,) frame rate of each view, frames per second.
        time_offset_s: (V,) reference time of each view's frame 0, seconds (view 0: 0).
        reference_fps: the reference clock's frame rate (``SceneConfig.fps``), frames per second.
        frames: per view, the (N_v,) frame numbers it films inside the generated motion (its own numbering).
        reference_frames: frames of the generated motion on the reference clock (covers every view's frames).
    """

    fps: np.ndarray
    time_offset_s: np.ndarray
    reference_fps: float
    frames: tuple[np.ndarray, ...]
    reference_frames: int

    @property
    def synced(self) -> bool:
        """Whether every view films the reference frames themselves (no offsets, every view at the scene's fps)."""
        return bool(np.all(self.time_offset_s == 0.0) and np.all(self.fps == self.reference_fps))

    def times_s(self, view: int, frames: np.ndarray) -> np.ndarray:
        """(N,) reference times, seconds, of the view's frames ``frames`` (its own numbers): ``n / fps_v + offset_v``."""
        return np.asarray(frames, dtype=np.float64) / self.fps[view] + self.time_offset_s[view]

    def table(self, sequence: str) -> pd.DataFrame:
        """One row per view: ``sequence, view, fps, time_offset_s, time_offset_frames`` (the offset in the view's
        frames, ``offset_v * fps_v``), ``first_frame, last_frame`` (the view's own numbers of the frames it films),
        ``num_frames``."""
        return pd.DataFrame({
            "sequence": np.full(len(self.fps), sequence, dtype=object),
            "view": np.arange(len(self.fps)),
            "fps": self.fps,
            "time_offset_s": self.time_offset_s,
            "time_offset_frames": self.time_offset_s * self.fps,
            "first_frame": [int(f[0]) if len(f) else -1 for f in self.frames],
            "last_frame": [int(f[-1]) if len(f) else -1 for f in self.frames],
            "num_frames": [len(f) for f in self.frames],
        })


def synced_clocks(config: SceneConfig) -> ViewClocks:
    """The clocks of a synchronised scene: every view films frames ``0..num_frames-1`` at the scene's fps."""
    frames = np.arange(config.num_frames)
    return ViewClocks(fps=np.full(config.num_views, config.fps), time_offset_s=np.zeros(config.num_views),
                      reference_fps=config.fps, frames=tuple(frames for _ in range(config.num_views)),
                      reference_frames=config.num_frames)


def draw_clocks(config: SceneConfig, rng: np.random.Generator) -> ViewClocks:
    """Each view's frame rate (one of ``config.view_fps_choices``, uniformly; the scene's fps without choices) and
    time offset (uniform in ``config.time_offset_range_s``; view 0: 0), and the frames each view films.

    Every view films the same span of the scene: ``num_frames / fps`` seconds from the moment the last camera started
    (``max(0, max_v offset_v)``), each at its own rate, as if the videos had been trimmed to the span all of them
    recorded; the motion is generated from reference time 0 long enough to cover it. A view's frame numbers are its
    own: its first filmed frame is ``ceil((start - offset_v) fps_v)``, not 0, for a view started before the last one.

    Args:
        config: the scene config (its ``view_fps_choices`` and ``time_offset_range_s``).
        rng: the clocks' own stream (the scene's other draws do not depend on it).

    Returns:
        The :class:`ViewClocks`.
    """
    num = config.num_views
    if config.view_fps_choices is None:
        fps = np.full(num, config.fps)
    else:
        fps = np.asarray(config.view_fps_choices, dtype=np.float64)[rng.integers(len(config.view_fps_choices),
                                                                                 size=num)]
    offset = np.zeros(num)
    if config.time_offset_range_s != (0.0, 0.0):
        offset[1:] = rng.uniform(*config.time_offset_range_s, num - 1)
    frames, last_time = [], 0.0
    start_s = max(0.0, float(offset.max()))
    for v in range(num):
        first = max(0, int(np.ceil((start_s - offset[v]) * fps[v] - _EPS_FRAMES)))
        count = max(1, int(round(config.duration_s * fps[v])))
        view_frames = np.arange(first, first + count)
        frames.append(view_frames)
        last_time = max(last_time, float(view_frames[-1] / fps[v] + offset[v]))
    # the last filmed time must lie strictly inside the motion, so that it has a next frame to interpolate towards
    reference_frames = max(config.num_frames, int(np.floor(last_time * config.fps + _EPS_FRAMES)) + 2)
    return ViewClocks(fps=fps, time_offset_s=offset, reference_fps=config.fps, frames=tuple(frames),
                      reference_frames=reference_frames)


def _bracket(clocks: ViewClocks, view: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reference frames before and after each of the view's frames and the interpolation weight of the later one."""
    u = clocks.times_s(view, clocks.frames[view]) * clocks.reference_fps
    before = np.floor(u + _EPS_FRAMES).astype(np.int64)
    weight = np.clip(u - before, 0.0, 1.0)
    weight[weight < _EPS_FRAMES] = 0.0  # on a reference frame up to round-off: that frame exactly
    before = np.clip(before, 0, clocks.reference_frames - 1)
    after = np.minimum(before + 1, clocks.reference_frames - 1)
    return before, after, weight


def keypoints_at(keypoints_world_m: np.ndarray, clocks: ViewClocks, view: int) -> np.ndarray:
    """The people's keypoints at the times of the view's frames, linearly interpolated between the two reference
    frames around each time (joint positions in the world, not rotations: at 25-60 fps a joint moves a few
    centimetres between frames, along an arc whose chord differs from it by well under a millimetre).

    Args:
        keypoints_world_m: (P, F_ref, J, 3) keypoints on the reference clock, metres.
        clocks: the views' clocks (``clocks.reference_frames == F_ref``).
        view: which view.

    Returns:
        (P, N_v, J, 3) keypoints at the view's frames ``clocks.frames[view]``, metres.
    """
    before, after, weight = _bracket(clocks, view)
    w = weight[None, :, None, None]
    return (1.0 - w) * keypoints_world_m[:, before] + w * keypoints_world_m[:, after]


def hidden_at(hidden: np.ndarray | None, clocks: ViewClocks, view: int) -> np.ndarray | None:
    """(P, N_v) whether each person is out of every view at the view's frames: out at either reference frame around
    the frame's time (``hidden``: (P, F_ref) on the reference clock, or None for nobody ever)."""
    if hidden is None:
        return None
    before, after, weight = _bracket(clocks, view)
    return hidden[:, before] | (hidden[:, after] & (weight > 0.0))


def to_reference_frames(detections: pd.DataFrame, fps: np.ndarray, time_offset_s: np.ndarray,
                        reference_fps: float, *, interpolate: bool = False) -> pd.DataFrame:
    """Detections moved onto the reference clock with known clocks (an oracle synchronisation, for evaluation):
    for every reference frame ``m`` each view gives its frame nearest in time, ``n = round((m / reference_fps -
    offset_v) fps_v)``, relabelled ``m``; the view's other frames are dropped (a 60 fps view gives every other
    frame to a 30 fps reference). The remaining error is the sub-frame part: at most half a frame of the slower clock.
    With ``interpolate``, each view's people at the reference frame's time instead, blended between the two frames
    around it along the view's 2D tracks (:func:`humancal.sync.interpolate.view_at_times`).

    Args:
        detections: a canonical ``detections`` table whose ``frame`` column holds each view's own frame numbers.
        fps: (V,) frame rate of each view, frames per second.
        time_offset_s: (V,) reference time of each view's frame 0, seconds.
        reference_fps: frame rate of the reference clock, frames per second.
        interpolate: blend between frames, not take the nearest.

    Returns:
        The detections with ``frame`` on the reference clock (rows of frames that land before reference frame 0 are
        dropped).
    """
    fps = np.asarray(fps, dtype=np.float64)
    offset = np.asarray(time_offset_s, dtype=np.float64)
    view = detections["view"].to_numpy()
    n = detections["frame"].to_numpy()
    reference = np.rint((n / fps[view] + offset[view]) * reference_fps).astype(np.int64)
    if interpolate:
        return _interpolated(detections, fps, offset, reference_fps, int(reference.max(initial=-1)))
    # the view's frame nearest to the reference frame's time: keep a row only if its frame is that one
    nearest = np.rint((reference / reference_fps - offset[view]) * fps[view]).astype(np.int64)
    keep = (nearest == n) & (reference >= 0)
    return detections.loc[keep].assign(frame=reference[keep]).reset_index(drop=True)


def _interpolated(detections: pd.DataFrame, fps: np.ndarray, offset: np.ndarray, reference_fps: float,
                  last: int) -> pd.DataFrame:
    """:func:`to_reference_frames` with ``interpolate``: every view at the reference frames ``0 .. last``."""
    from humancal.sync.interpolate import views_at_times

    times = np.arange(last + 1) / reference_fps
    views = np.unique(detections["view"].to_numpy())
    return views_at_times(detections, {int(v): (times - offset[v]) * fps[v] for v in views})[0]


def started_by_hand(detections: pd.DataFrame, starts, num_frames: int) -> pd.DataFrame:
    """A synced scene's detections as cameras started by hand would have filmed them: view ``v`` keeps the
    ``num_frames`` frames from its reference frame ``starts[v]`` on, numbered from 0 (so its time offset from view 0
    is ``(starts[v] - starts[0]) / fps``, whole frames).

    Args:
        detections: canonical ``detections`` table on the reference clock.
        starts: (V,) each view's first reference frame.
        num_frames: frames each view films.
    """
    parts = []
    for v, start in enumerate(starts):
        d = detections[(detections["view"] == v) & (detections["frame"] >= start)
                       & (detections["frame"] < start + num_frames)].copy()
        d["frame"] = (d["frame"] - start).astype(detections["frame"].dtype)
        parts.append(d)
    return pd.concat(parts, ignore_index=True)
