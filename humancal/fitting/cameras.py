"""The cameras as variables of a fit: which parameters move (``CAMERA_REGIMES``) and their parametrisation.

Regimes (the paper's Tables; ``docs/refinement.md``):

* ``fixed``: the cameras are held (a fit with known, or separately calibrated, cameras);
* ``ext``: the extrinsics move, the intrinsics are known (held);
* ``int_ext``: the focal length and the extrinsics move (fully self-calibrated).

Parametrisation per view, chosen so that every variable is of order one and none is tied to the world origin:

* the focal length as ``f = f0 exp(log_focal)`` (``fx`` and ``fy`` scale together: their ratio is kept);
* the orientation as a rotation vector ``w`` (radians) applied in the camera frame:
  ``R_cam_from_world = exp([w]_x) R0``;
* the optical centre ``c_world_m`` (metres) rather than the translation ``t = -R c``, so that a rotation of a camera
  does not swing it around the world origin.

The principal point stays where it is (the image centre unless known). The radial coefficient ``k1`` may move per
view (``refine_k1``; off by default: the people rarely reach the image corners where it is observable).
"""

from __future__ import annotations

import numpy as np
import roma
import torch
from torch import Tensor

from humancal.camera import CameraRig, RigTensors

__all__ = ["CAMERA_REGIMES", "CameraVariables", "camera_shift_px"]

CAMERA_REGIMES = ("fixed", "ext", "int_ext")
"""Which camera parameters a fit moves (module docstring)."""


class CameraVariables:
    """A rig whose parameters are torch variables of a fit.

    Args:
        rig: the initial V cameras.
        regime: one of :data:`CAMERA_REGIMES`.
        refine_k1: whether the first radial distortion coefficient moves too (not with ``fixed``).
        dtype, device: of the tensors.
    """

    def __init__(self, rig: CameraRig, regime: str = "int_ext", *, refine_k1: bool = False,
                 dtype: torch.dtype = torch.float64, device: torch.device | str = "cpu") -> None:
        if regime not in CAMERA_REGIMES:
            raise ValueError(f"camera regime {regime!r} must be one of {list(CAMERA_REGIMES)}")
        self.regime, self.refine_k1 = regime, bool(refine_k1) and regime != "fixed"
        self.image_size_px = rig.image_size_px.copy()
        initial = rig.to_torch(dtype=dtype, device=device)
        self.K0, self.R0, self.distortion0 = initial.K, initial.R_cam_from_world, initial.distortion
        V = len(rig)
        as_t = lambda a: torch.as_tensor(a, dtype=dtype, device=device)  # noqa: E731
        moves = regime != "fixed"
        self.log_focal = torch.zeros(V, dtype=dtype, device=device).requires_grad_(regime == "int_ext")
        self.rotvec = torch.zeros(V, 3, dtype=dtype, device=device).requires_grad_(moves)
        self.centre_m = as_t(rig.centers_world_m).clone().requires_grad_(moves)
        self.k1 = self.distortion0[:, 0].clone().requires_grad_(self.refine_k1)

    def __len__(self) -> int:
        return int(self.K0.shape[0])

    @property
    def moves(self) -> bool:
        return self.regime != "fixed"

    def variables(self) -> list[Tensor]:
        """The tensors a camera stage optimises (empty for ``fixed``)."""
        return [v for v in (self.log_focal, self.rotvec, self.centre_m, self.k1) if v.requires_grad]

    _NAMES = ("log_focal", "rotvec", "centre_m", "k1")

    def _moving(self) -> list[str]:
        return [name for name in self._NAMES if getattr(self, name).requires_grad]

    def parameters(self) -> Tensor:
        """(V, p) the moving variables side by side (in ``log_focal, rotvec, centre_m, k1`` order; p = 0 for
        ``fixed``), differentiable back to them."""
        columns = [getattr(self, name) for name in self._moving()]
        return torch.cat([c if c.ndim == 2 else c.unsqueeze(-1) for c in columns], dim=-1) if columns else \
            self.log_focal.detach().new_zeros(len(self), 0)

    def unpack(self, theta: Tensor) -> dict[str, Tensor]:
        """All four variables (keyword arguments of :meth:`tensors_at`) with the moving ones read from ``theta``
        ((V, p), as :meth:`parameters`) and the others at their current values."""
        values, column = {name: getattr(self, name).detach() for name in self._NAMES}, 0
        for name in self._moving():
            width = 3 if values[name].ndim == 2 else 1
            part = theta[:, column:column + width]
            values[name] = part if width == 3 else part[:, 0]
            column += width
        return values

    def assign(self, theta: Tensor) -> None:
        """Set the moving variables to ``theta`` ((V, p), as :meth:`parameters`)."""
        with torch.no_grad():
            for name, value in self.unpack(theta).items():
                if getattr(self, name).requires_grad:
                    getattr(self, name).copy_(value)

    def tensors(self) -> RigTensors:
        """The current rig as differentiable tensors (:meth:`RigTensors.project` projects through it)."""
        return self.tensors_at(self.log_focal, self.rotvec, self.centre_m, self.k1)

    def tensors_at(self, log_focal: Tensor, rotvec: Tensor, centre_m: Tensor, k1: Tensor) -> RigTensors:
        """The rig at other values of the variables (same shapes: (V,), (V, 3), (V, 3), (V,)), for solvers that
        differentiate through it functionally (``torch.func``)."""
        scale = torch.exp(log_focal)
        # only fx and fy scale (the principal point and skew stay): K0 + diag(fx (s - 1), fy (s - 1), 0)
        K = self.K0 + torch.diag_embed(torch.stack([self.K0[:, 0, 0] * (scale - 1.0),
                                                    self.K0[:, 1, 1] * (scale - 1.0),
                                                    torch.zeros_like(scale)], dim=-1))
        R = roma.rotvec_to_rotmat(rotvec) @ self.R0
        t = -torch.einsum("vij,vj->vi", R, centre_m)
        distortion = torch.cat([k1.unsqueeze(-1), self.distortion0[:, 1:]], dim=-1)
        return RigTensors(K, R, t, distortion)

    def to_rig(self) -> CameraRig:
        """The current cameras as a :class:`CameraRig` (float64 arrays)."""
        with torch.no_grad():
            rig = self.tensors()
            as_np = lambda t: t.detach().cpu().double().numpy()  # noqa: E731
            return CameraRig(as_np(rig.K), as_np(rig.R_cam_from_world), as_np(rig.t_cam_from_world_m),
                             as_np(rig.distortion), np.asarray(self.image_size_px))

    def shift_world(self, offset_m: Tensor) -> None:
        """Move the world origin by ``-offset_m`` (the cameras' centres move by ``-offset_m``; (3,) metres)."""
        with torch.no_grad():
            self.centre_m -= offset_m


def camera_shift_px(cameras: CameraVariables, before: Tensor, points_world_m: Tensor) -> float:
    """How far a change of the cameras moves what they see: the mean distance, pixels, between ``points_world_m``
    ((N, 3), metres) projected through the cameras at ``before`` ((V, p), :meth:`CameraVariables.parameters`) and
    through the cameras now, over every view and every point in front of the camera both times (NaN: none)."""
    with torch.no_grad():
        old, _, front_old = cameras.tensors_at(**cameras.unpack(before)).project(points_world_m)
        new, _, front_new = cameras.tensors().project(points_world_m)
        seen = front_old & front_new
        return float((new - old).norm(dim=-1)[seen].mean()) if bool(seen.any()) else float("nan")
