"""The Human3.6M camera calibration file (external data, ``h36m_cameras``) and the point its cameras look at, for
the synthetic rig ``"h36m"`` (:func:`humancal.synthetic.rigs.h36m_rig`)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

__all__ = ["load_h36m_cameras", "axes_meeting_point"]


def load_h36m_cameras(path: Path, subject: str) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
    """Read the Human3.6M calibration of one subject.

    Args:
        path: ``camera-parameters.json`` (format in the dataset's ``SOURCE.md``: world in millimetres,
            ``P = K [R | t]``).
        subject: ``"S1"`` .. ``"S11"``.

    Returns:
        Per camera, in file order: (camera id, K (3, 3) pixels, R_cam_from_world (3, 3),
        t_cam_from_world_m (3,) metres).

    Raises:
        ValueError: the file does not have the documented structure (naming the missing part).
    """
    try:
        data = json.loads(path.read_text())
        intrinsics_by_id = data["intrinsics"]
        extrinsics = data["extrinsics"][subject]
    except (KeyError, json.JSONDecodeError) as err:
        raise ValueError(
            f"{path}: expected {{'intrinsics': {{id: ...}}, 'extrinsics': {{'{subject}': {{id: {{R, t}}}}}}}}; "
            f"missing or invalid: {err}"
        ) from None
    out = []
    for camera_id, K_list in ((cid, intrinsics_by_id[cid]["calibration_matrix"]) for cid in intrinsics_by_id):
        if camera_id not in extrinsics:
            raise ValueError(f"{path}: camera {camera_id} has no extrinsics for subject {subject}")
        K = np.asarray(K_list, dtype=np.float64)
        R = np.asarray(extrinsics[camera_id]["R"], dtype=np.float64)
        t_mm = np.asarray(extrinsics[camera_id]["t"], dtype=np.float64).reshape(-1)
        if K.shape != (3, 3) or R.shape != (3, 3) or t_mm.shape != (3,):
            raise ValueError(
                f"{path}: camera {camera_id} of {subject}: expected K 3x3, R 3x3, t 3x1; got {K.shape}, {R.shape}, "
                f"{t_mm.shape}"
            )
        out.append((camera_id, K, R, t_mm / 1000.0))
    return out


def axes_meeting_point(centers: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Least-squares point closest to all lines ``center + s * direction`` (unit directions)."""
    projector = np.eye(3)[None] - directions[:, :, None] * directions[:, None, :]
    return np.linalg.solve(projector.sum(axis=0), (projector @ centers[:, :, None]).sum(axis=0)[:, 0])
