"""The result type shared by the mocap readers: joint world positions of one clip.

Convention (``docs/conventions.md``, ``docs/mocap.md``): world metres, right-handed, Z up, floor at z = 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["MocapClip", "MocapFormatError"]


class MocapFormatError(ValueError):
    """A mocap file does not hold what its format promises.

    The message names the file, the 1-based line (when one is to blame) and what was expected there.

    Attributes:
        path: the file that failed to parse.
        line: 1-based line number, or ``None`` when the problem is not tied to one line.
    """

    def __init__(self, path: str | Path, line: int | None, message: str) -> None:
        self.path = Path(path)
        self.line = line
        where = f"{self.path}, line {line}" if line is not None else f"{self.path}"
        super().__init__(f"{where}: {message}")


@dataclass(frozen=True)
class MocapClip:
    """Joint positions of one mocap clip, in the world frame.

    Attributes:
        name: clip name, e.g. ``"02_01"`` (the file name without its extensions).
        subject: subject id, e.g. ``"02"``.
        joint_names: (J,) joint names, parents before children.
        parents: (J,) index of each joint's parent in ``joint_names``; -1 for a root.
        positions_world_m: (F, J, 3) joint positions, metres, world frame: right-handed, Z up, floor z = 0.
            Stored as a read-only float64 array.
        fps: frames per second of ``positions_world_m``.
        source_path: the file the clip was read from (``None`` for derived clips without one).
    """

    name: str
    subject: str
    joint_names: tuple[str, ...]
    parents: tuple[int, ...]
    positions_world_m: np.ndarray
    fps: float
    source_path: Path | None = None

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.joint_names)
        parents = tuple(int(p) for p in self.parents)
        positions = np.array(self.positions_world_m, dtype=np.float64, copy=True)
        if positions.ndim != 3 or positions.shape[2] != 3:
            raise ValueError(f"MocapClip {self.name!r}: positions_world_m must be (F, J, 3), got {positions.shape}")
        if len(names) != positions.shape[1] or len(parents) != positions.shape[1]:
            raise ValueError(
                f"MocapClip {self.name!r}: {positions.shape[1]} joints in positions_world_m but "
                f"{len(names)} joint_names and {len(parents)} parents"
            )
        if len(set(names)) != len(names):
            raise ValueError(f"MocapClip {self.name!r}: joint names must be unique, got {names}")
        for j, p in enumerate(parents):
            if not -1 <= p < j:
                raise ValueError(
                    f"MocapClip {self.name!r}: parent of joint {j} ({names[j]!r}) is {p}; expected -1 (root) "
                    f"or the index of an earlier joint"
                )
        if not np.all(np.isfinite(positions)):
            raise ValueError(f"MocapClip {self.name!r}: positions_world_m holds non-finite values")
        fps = float(self.fps)
        if not (np.isfinite(fps) and fps > 0):
            raise ValueError(f"MocapClip {self.name!r}: fps must be positive and finite, got {self.fps!r}")
        positions.setflags(write=False)
        object.__setattr__(self, "joint_names", names)
        object.__setattr__(self, "parents", parents)
        object.__setattr__(self, "positions_world_m", positions)
        object.__setattr__(self, "fps", fps)
        if self.source_path is not None:
            object.__setattr__(self, "source_path", Path(self.source_path))

    @property
    def frames(self) -> int:
        """Number of frames F."""
        return int(self.positions_world_m.shape[0])

    @property
    def duration_s(self) -> float:
        """Clip duration in seconds, ``frames / fps`` (each frame stands for one sampling interval)."""
        return self.frames / self.fps

    def joint_index(self, name: str) -> int:
        """Index of the joint ``name``.

        Raises:
            KeyError: naming the clip and the joints it has.
        """
        try:
            return self.joint_names.index(name)
        except ValueError:
            raise KeyError(f"clip {self.name!r} has no joint {name!r}; joints: {', '.join(self.joint_names)}") from None

    def bone_lengths_m(self) -> np.ndarray:
        """Distance of every joint to its parent, per frame.

        Returns:
            (F, J) metres; 0 for roots.
        """
        parents = np.array(self.parents)
        safe = np.where(parents < 0, np.arange(len(parents)), parents)
        return np.linalg.norm(self.positions_world_m - self.positions_world_m[:, safe], axis=-1)

    def trimmed(self, start: int, stop: int | None = None) -> MocapClip:
        """The frames ``start:stop`` (Python slice semantics, step 1) as a new clip.

        Raises:
            ValueError: the range holds no frame.
        """
        positions = self.positions_world_m[start:stop]
        if positions.shape[0] == 0:
            raise ValueError(f"trimmed: frames {start}:{stop} of clip {self.name!r} ({self.frames} frames) are empty")
        return MocapClip(self.name, self.subject, self.joint_names, self.parents, positions, self.fps, self.source_path)

    def resample(self, fps_out: float) -> MocapClip:
        """The clip at another frame rate, by linear interpolation of joint positions in time.

        Output frame k is taken at time ``k / fps_out`` from the first frame, for every such time up to
        the last input frame, ``(F - 1) / fps``; so the first frame is kept and nothing is extrapolated.
        Positions (not rotations) are interpolated, so between two input frames a bone is slightly shorter
        than its length (a chord of the arc its end sweeps); at the 120 fps of the CMU clips this is far below
        a millimetre for ordinary motion.

        Args:
            fps_out: the new frame rate, frames per second, > 0.

        Returns:
            A new clip with ``fps == fps_out`` and the same joints.

        Raises:
            ValueError: ``fps_out`` is not a positive finite number.
        """
        fps_out = float(fps_out)
        if not (np.isfinite(fps_out) and fps_out > 0):
            raise ValueError(f"resample: fps_out must be positive and finite, got {fps_out!r}")
        last_s = (self.frames - 1) / self.fps
        # The small tolerance keeps an exact multiple (e.g. 120 -> 30 fps) from losing its last frame to rounding.
        n_out = int(np.floor(last_s * fps_out + 1e-9)) + 1
        t_in = np.arange(self.frames) / self.fps
        t_out = np.arange(n_out) / fps_out
        pos = self.positions_world_m
        i0 = np.clip(np.searchsorted(t_in, t_out, side="right") - 1, 0, self.frames - 1)
        i1 = np.minimum(i0 + 1, self.frames - 1)
        span = np.where(i1 > i0, t_in[i1] - t_in[i0], 1.0)
        w = np.clip((t_out - t_in[i0]) / span, 0.0, 1.0)[:, None, None]
        resampled = (1.0 - w) * pos[i0] + w * pos[i1]
        return MocapClip(
            name=self.name,
            subject=self.subject,
            joint_names=self.joint_names,
            parents=self.parents,
            positions_world_m=resampled,
            fps=fps_out,
            source_path=self.source_path,
        )
