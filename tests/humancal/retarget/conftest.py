"""Fixtures of the retarget tests: a synthetic "mocap" clip made by the body model itself, and real CMU clips."""

import math

import numpy as np
import pytest
import roma
import torch

from humancal.mocap import MocapClip, read_bvh
from humancal.retarget import RetargetConfig, resolve_links
from humancal.retarget.priors import PoseWeights
from humancal.retarget.points import PointModel
from humancal.retarget.threads import torch_threads
from humancal.settings import DataRootError, dataset_dir

TRUE_PHENOTYPES = np.array([0.3, 0.75, 0.55, 0.45, 0.35, 0.6])


@pytest.fixture(autouse=True)
def one_torch_thread():
    """The solvers' internals run here without the public functions' thread guard: one thread, as they do."""
    with torch_threads(1):
        yield


def synthetic_motion(body_model, num_frames: int, seed: int = 0, hinges=None):
    """A smooth, deterministic pose sequence: every joint swings (up to ~0.5 rad), the body walks and turns.

    Twists no point observes (toes) stay at identity, so that the ground truth is recoverable. With ``hinges``
    (a ``PoseWeights``), knees and elbows only flex about their axes (0 to 1.2 rad), as real ones do.
    """
    generator = torch.Generator().manual_seed(seed)
    num_bones = body_model.num_posed_bones
    t = torch.arange(num_frames, dtype=torch.float64) / 30.0
    axes = torch.nn.functional.normalize(torch.randn(num_bones, 3, generator=generator, dtype=torch.float64), dim=-1)
    amplitude = 0.15 + 0.35 * torch.rand(num_bones, generator=generator, dtype=torch.float64)
    frequency = 0.5 + torch.rand(num_bones, generator=generator, dtype=torch.float64)
    phase = 2 * math.pi * torch.rand(num_bones, generator=generator, dtype=torch.float64)
    angle = amplitude * torch.sin(2 * math.pi * frequency * t[:, None] + phase)
    rotvec = axes * angle[..., None]
    toes = [body_model.posed_bones.index("toes.L"), body_model.posed_bones.index("toes.R")]
    rotvec[:, toes] = 0.0
    rotvec[:, 0] = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64) * (0.6 * t)[:, None]  # turning, upright
    if hinges is not None:
        for i, b in enumerate(hinges.hinge_bones.tolist()):
            flexion = 0.6 + 0.6 * torch.sin(2 * math.pi * frequency[b] * t + phase[b])
            rotvec[:, b] = hinges.hinge_axes[i] * flexion[:, None]
    rotmats = roma.rotvec_to_rotmat(rotvec)
    translation = torch.stack([0.8 * t, 0.2 * torch.sin(t), torch.full_like(t, 0.95)], dim=-1)
    return rotmats, translation


_FREE_OFFSETS_M = {  # left-side / midline values of the size a CMU fit finds (docs/retarget.md)
    "lThigh": (-0.025, -0.01, -0.03),
    "head": (0.0, 0.02, -0.05),
    "leftEye": (0.009, 0.02, -0.06),
    "lIndex1": (0.035, -0.08, -0.025),
    "lPinky1": (0.06, -0.03, -0.04),
}


def synthetic_offsets(points: PointModel, rest, seed: int = 1) -> torch.Tensor:
    """Offsets like the CMU ones: lengths of up to 3 cm along segments, free offsets as in ``_FREE_OFFSETS_M``."""
    generator = torch.Generator().manual_seed(seed)
    basis = points.offset_basis(rest)
    raw = torch.zeros(points.num_points, 3, dtype=torch.float64)
    for m, name in enumerate(points.resolved.mocap_joints):
        twin = points.resolved.mocap_joints[int(points.resolved.mirror[m])]
        if name in _FREE_OFFSETS_M:
            raw[m] = torch.tensor(_FREE_OFFSETS_M[name], dtype=torch.float64)
        elif twin in _FREE_OFFSETS_M:
            raw[m] = torch.tensor(_FREE_OFFSETS_M[twin], dtype=torch.float64) * torch.tensor([-1.0, 1.0, 1.0])
    coordinates = basis.T @ raw.reshape(-1)
    along = torch.tensor([kind == "along" for kind in points.offset_column_kinds()])
    lengths = 0.03 * (2 * torch.rand(int(along.sum()), generator=generator, dtype=torch.float64) - 1)
    coordinates[along] = lengths
    return (basis @ coordinates).reshape(-1, 3)


def make_synthetic_clip(body_model, num_frames=48, name="91_01", phenotypes=TRUE_PHENOTYPES, seed=0):
    """(clip, truth): a MocapClip holding the mapped points of a known body, and the truth behind it."""
    config = RetargetConfig()
    resolved = resolve_links(config.links, body_model.posed_bones, body_model.posed_parents)
    points = PointModel(body_model, resolved)
    with torch.no_grad():
        rest = body_model.rest_skeleton(torch.as_tensor(phenotypes, dtype=body_model.dtype)[None])
        offsets = synthetic_offsets(points, rest, seed=seed + 1)
        hinges = PoseWeights.from_config(config, points, points.coefficients(rest, offsets))
        rotmats, translation = synthetic_motion(body_model, num_frames, seed=seed, hinges=hinges)
        positions = points.points(points.coefficients(rest, offsets), rotmats, translation)
        keypoints = body_model.keypoints(rest, rotmats.float()[None], translation.float()[None])[0]
    clip = MocapClip(
        name=name,
        subject=name.split("_")[0],
        joint_names=resolved.mocap_joints,
        parents=(-1,) * resolved.num_points,
        positions_world_m=positions.numpy(),
        fps=30.0,
    )
    truth = {
        "phenotypes": np.asarray(phenotypes, dtype=np.float64),
        "offsets_m": offsets.numpy(),
        "rotmats": rotmats.numpy(),
        "translation": translation.numpy(),
        "keypoints": keypoints.double().numpy(),
        "rest": rest,
    }
    return clip, truth


@pytest.fixture(scope="session")
def synthetic_clip(body_model):
    return make_synthetic_clip(body_model)


@pytest.fixture(scope="session")
def make_clip(body_model):
    """``make_clip(num_frames, name, seed=0)``: another synthetic clip and its truth."""
    return lambda num_frames, name, seed=0: make_synthetic_clip(body_model, num_frames, name, seed=seed)


@pytest.fixture(scope="session")
def cmu_clips():
    """Two short real clips (2 s each, walk and run) of CMU subject 02, with the End Sites; skip without data."""
    try:
        root = dataset_dir("cmu_mocap")
    except DataRootError as err:
        pytest.skip(f"CMU mocap data not available: {err}")
    paths = [root / "bvh_daz" / "02" / "02_01.bvh.gz", root / "bvh_daz" / "02" / "02_03.bvh.gz"]
    missing = [p for p in paths if not p.is_file()]
    if missing:
        pytest.skip(f"CMU clips missing: {missing}")
    return [read_bvh(p, include_end_sites=True).trimmed(0, 240) for p in paths]
