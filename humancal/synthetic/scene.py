"""Generate a whole synthetic scene: people, motions, cameras and detections, as canonical tables.

Randomness: one ``numpy.random.Generator`` seeded with ``config.seed`` spawns one independent child stream
per stage (people, motions, cameras, detector, detection ids, out-of-view spells, keypoint bias, view clocks), so the
same config gives the same scene bit for bit, and changing e.g. only the noise model leaves people, motions and
cameras unchanged.

Unsynchronised videos (``time_offset_range_s``, ``view_fps_choices``; :mod:`humancal.synthetic.clocks`): the motion
is generated on the reference clock long enough to cover every view's frames, each view sees the people's keypoints
linearly interpolated at its own frames' times, and its detections carry its own frame numbers.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd
import torch

from humancal.body import PHENOTYPE_NAMES, BodyModel, RestSkeleton
from humancal.camera import CameraRig, cameras_to_table
from humancal.keypoints import CANONICAL_JOINTS, NUM_JOINTS
from humancal.synthetic.clocks import ViewClocks, draw_clocks, hidden_at, keypoints_at, synced_clocks
from humancal.synthetic.config import OUT_OF_VIEW_DURATION_S, SceneConfig
from humancal.synthetic.motions import Motions, generate_motions
from humancal.synthetic.noise import DetectorOutput, draw_keypoint_bias, simulate_detections, simulate_view_detections
from humancal.synthetic.people import People, sample_people
from humancal.synthetic.rigs import make_rig
from humancal.tables.schemas import validate_table

__all__ = ["SyntheticScene", "generate_scene", "ProgressCallback"]

logger = logging.getLogger(__name__)

ProgressCallback = Callable[[str, float], None]
"""Called as ``progress(stage, fraction_done)`` after each stage; fraction in [0, 1]."""

_JOINT_NAMES = np.array(CANONICAL_JOINTS, dtype=object)


@dataclass(frozen=True)
class SyntheticScene:
    """A generated scene with ground truth for everything.

    Tables (pandas DataFrames, validated against ``humancal.tables.schemas.SCHEMAS``):

    Attributes:
        detections: canonical ``detections``: one row per reported joint; ``det_id`` is a random
            permutation within each (frame, view), so its order says nothing about identity. ``frame`` is each view's
            own frame number (the reference frame itself unless the views are unsynchronised: ``clocks``).
        cameras: canonical ``cameras`` of the rig.
        poses3d: canonical ``poses3d``: ground-truth 23 keypoints of every person and frame (valid = True).
        associations: canonical ``associations``: the true person of every detection, -1 for false positives
            (keyed like ``detections``: each view's own frame numbers).
        people: canonical ``people``: phenotypes and height of every person.
        motions: canonical ``motions``: per person and frame, ``bone_rotmats_local`` (B x 3 x 3 flattened
            row-major, bones in ``BodyModel.posed_bones`` order), ``root_translation_m``, ``phenotypes``,
            ``keypoints_world_m`` (23 x 3 flattened).

    Raw data:

    Attributes:
        config: the :class:`SceneConfig` it was made from.
        sequence: the sequence name written into every table.
        rig: the V cameras (a :class:`~humancal.camera.CameraRig`, a sequence of cameras in view order).
        person_ids: (P,) person ids.
        phenotypes: (P, 6) anny phenotypes, columns ``humancal.body.PHENOTYPE_NAMES``.
        height_m: (P,) standing heights, metres.
        bone_rotmats_local: (P, F, B, 3, 3) body-model pose.
        root_translation_m: (P, F, 3) root positions, metres.
        keypoints_world_m: (P, F, 23, 3) ground-truth keypoints, metres.
        activity: (P, F) activity code (``humancal.synthetic.activities.ACTIVITIES``).
        detector: the :class:`DetectorOutput` (per-detection arrays and per-view truth: visibility,
            occlusion, eligibility, flips).
        det_id: (N,) the det_id of each detection of ``detector``.
        keypoint_bias_m: (23, 3) the detector's keypoint offsets in their bones, metres
            (``DetectorNoise.keypoint_bias_m``; zeros without a bias).
        clocks: the views' clocks (:class:`~humancal.synthetic.clocks.ViewClocks`): per view its frame rate
            ``clocks.fps`` (V,), frames per second, its time offset ``clocks.time_offset_s`` (V,), seconds (the
            reference time of its frame 0; view 0: 0) and the frames it films; ``view_clocks`` is the same as a table.
            A synchronised scene: every view at ``config.fps``, offsets 0, frames ``0..F-1``.
    """

    config: SceneConfig
    sequence: str
    detections: pd.DataFrame
    cameras: pd.DataFrame
    poses3d: pd.DataFrame
    associations: pd.DataFrame
    people: pd.DataFrame
    motions: pd.DataFrame
    rig: CameraRig
    person_ids: np.ndarray
    phenotypes: np.ndarray
    height_m: np.ndarray
    bone_rotmats_local: np.ndarray
    root_translation_m: np.ndarray
    keypoints_world_m: np.ndarray
    activity: np.ndarray
    detector: DetectorOutput
    det_id: np.ndarray
    keypoint_bias_m: np.ndarray
    clocks: ViewClocks

    @property
    def view_clocks(self) -> pd.DataFrame:
        """The true clock of every view, one row per view: ``sequence, view, fps, time_offset_s,
        time_offset_frames`` (offset in the view's own frames), ``first_frame, last_frame, num_frames`` (the frames it
        films, its own numbers); what an evaluation scores estimated time offsets against."""
        return self.clocks.table(self.sequence)

    def summary(self) -> dict[str, float | int]:
        """Counts and realised noise rates (for logs and asset metadata)."""
        d = self.detector
        eligible = int(d.eligible.sum())
        true_dets = d.person_id >= 0
        return {
            "people": int(self.person_ids.shape[0]),
            "views": len(self.rig),
            "frames": int(self.config.num_frames),
            "reference_frames": int(self.keypoints_world_m.shape[1]),
            "detections": d.num_detections,
            "detection_rows": len(self.detections),
            "false_positives": int((~true_dets).sum()),
            "eligible_person_views": eligible,
            "person_recall": float(d.detected.sum() / eligible) if eligible else float("nan"),
            "flip_fraction": float(d.flipped[true_dets].mean()) if true_dets.any() else float("nan"),
            "mean_score": float(self.detections["score"].mean()) if len(self.detections) else float("nan"),
        }


def _out_of_view(config: SceneConfig, num_frames: int, rng: np.random.Generator) -> np.ndarray | None:
    """(P, F) True where a person is out of every view (``config.out_of_view_spells``) in each of the ``num_frames``
    reference frames, or None for none."""
    if config.out_of_view_spells <= 0:
        return None
    hidden = np.zeros((config.num_people, num_frames), dtype=bool)
    counts = rng.poisson(config.out_of_view_spells, config.num_people)
    for person, count in enumerate(counts):
        duration = np.round(rng.uniform(*OUT_OF_VIEW_DURATION_S, count) * config.fps).astype(int)
        # a spell may start before the first frame or end after the last (entering late, leaving early)
        start = rng.integers(-duration // 2, num_frames - duration // 2)
        for first, length in zip(start, duration):
            hidden[person, max(first, 0):max(first + length, 0)] = True
    return hidden


def _assign_det_ids(frame: np.ndarray, view: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A random permutation 0..n-1 within each (frame, view) group."""
    key = rng.random(len(frame))
    order = np.lexsort((key, view, frame))
    group_frame, group_view = frame[order], view[order]
    new_group = np.ones(len(order), bool)
    new_group[1:] = (group_frame[1:] != group_frame[:-1]) | (group_view[1:] != group_view[:-1])
    group_start = np.maximum.accumulate(np.where(new_group, np.arange(len(order)), 0))
    det_id = np.empty(len(order), np.int64)
    det_id[order] = np.arange(len(order)) - group_start
    return det_id


def _constant(value: str, n: int) -> np.ndarray:
    return np.full(n, value, dtype=object)


def _detections_table(sequence: str, det: DetectorOutput, det_id: np.ndarray) -> pd.DataFrame:
    rows, joints = np.nonzero(det.present)
    order = np.lexsort((joints, det_id[rows], det.view[rows], det.frame[rows]))
    rows, joints = rows[order], joints[order]
    df = pd.DataFrame(
        {
            "sequence": _constant(sequence, len(rows)),
            "frame": det.frame[rows],
            "view": det.view[rows],
            "det_id": det_id[rows],
            "joint": _JOINT_NAMES[joints],
            "x_px": det.keypoints_px[rows, joints, 0],
            "y_px": det.keypoints_px[rows, joints, 1],
            "score": det.scores[rows, joints],
        }
    )
    return validate_table(df, "detections", source="synthetic scene")


def _associations_table(sequence: str, det: DetectorOutput, det_id: np.ndarray) -> pd.DataFrame:
    order = np.lexsort((det_id, det.view, det.frame))
    df = pd.DataFrame(
        {
            "sequence": _constant(sequence, len(order)),
            "frame": det.frame[order],
            "view": det.view[order],
            "det_id": det_id[order],
            "person_id": det.person_id[order],
        }
    )
    return validate_table(df, "associations", source="synthetic scene")


def _poses3d_table(sequence: str, person_ids: np.ndarray, keypoints_world_m: np.ndarray) -> pd.DataFrame:
    num_people, num_frames = keypoints_world_m.shape[:2]
    frame = np.broadcast_to(np.arange(num_frames)[:, None, None], (num_frames, num_people, NUM_JOINTS))
    person = np.broadcast_to(person_ids[None, :, None], (num_frames, num_people, NUM_JOINTS))
    joint = np.broadcast_to(np.arange(NUM_JOINTS)[None, None, :], (num_frames, num_people, NUM_JOINTS))
    points = keypoints_world_m.transpose(1, 0, 2, 3).reshape(-1, 3)
    n = points.shape[0]
    df = pd.DataFrame(
        {
            "sequence": _constant(sequence, n),
            "frame": frame.reshape(-1),
            "person_id": person.reshape(-1),
            "joint": _JOINT_NAMES[joint.reshape(-1)],
            "x_m": points[:, 0],
            "y_m": points[:, 1],
            "z_m": points[:, 2],
            "valid": np.ones(n, bool),
        }
    )
    return validate_table(df, "poses3d", source="synthetic scene")


def _people_table(sequence: str, people: People) -> pd.DataFrame:
    columns = {"sequence": _constant(sequence, people.num_people), "person_id": people.person_ids}
    columns.update({name: people.phenotypes[:, i] for i, name in enumerate(PHENOTYPE_NAMES)})
    columns["height_m"] = people.height_m
    return validate_table(pd.DataFrame(columns), "people", source="synthetic scene")


def _motions_table(sequence: str, people: People, motions: Motions) -> pd.DataFrame:
    num_people, num_frames = motions.root_translation_m.shape[:2]
    n = num_people * num_frames
    df = pd.DataFrame(
        {
            "sequence": _constant(sequence, n),
            "person_id": np.repeat(people.person_ids, num_frames),
            "frame": np.tile(np.arange(num_frames), num_people),
            "bone_rotmats_local": list(motions.bone_rotmats_local.reshape(n, -1)),
            "root_translation_m": list(motions.root_translation_m.reshape(n, 3)),
            "phenotypes": list(np.repeat(people.phenotypes, num_frames, axis=0)),
            "keypoints_world_m": list(motions.keypoints_world_m.reshape(n, -1)),
        }
    )
    return validate_table(df, "motions", source="synthetic scene")


def _detector_keypoints(
    config: SceneConfig, body: BodyModel, rest: RestSkeleton, motions: Motions, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """The (P, F, 23, 3) keypoints the detector sees, world metres, and its (23, 3) keypoint bias, metres: the
    ground truth and zeros, or (``DetectorNoise.keypoint_bias_m``) what the detector calls a joint, the model's
    keypoints moved in the bones by a drawn bias."""
    detected_m, bias_m = motions.keypoints_world_m, np.zeros((NUM_JOINTS, 3))
    if config.noise.keypoint_bias_m > 0:  # what the detector calls a joint: the model's keypoints moved in the bones
        bias_m = draw_keypoint_bias(config.noise.keypoint_bias_m, rng)
        offsets = torch.as_tensor(bias_m, dtype=body.dtype, device=body.device)
        with torch.no_grad():
            detected_m = body.keypoints(rest.with_keypoint_offsets(offsets),
                                        torch.as_tensor(motions.bone_rotmats_local, dtype=body.dtype,
                                                        device=body.device),
                                        torch.as_tensor(motions.root_translation_m, dtype=body.dtype,
                                                        device=body.device)).double().cpu().numpy()
    return detected_m, bias_m


def _simulate_detector(
    config: SceneConfig,
    clocks: ViewClocks,
    detected_m: np.ndarray,
    people: People,
    rig: CameraRig,
    hidden: np.ndarray | None,
    rng: np.random.Generator,
) -> DetectorOutput:
    """The simulated detections of every view, from the (P, F_ref, 23, 3) keypoints ``detected_m`` (world metres)
    on the reference clock: each view at its own frames' times when the views are unsynchronised."""
    if config.unsynced:
        views = range(len(rig))
        return simulate_view_detections([keypoints_at(detected_m, clocks, v) for v in views], list(clocks.frames),
                                        people.height_m, rig, config.noise, rng,
                                        [hidden_at(hidden, clocks, v) for v in views])
    return simulate_detections(detected_m, people.height_m, rig, config.noise, rng, hidden)


def _assemble_scene(
    config: SceneConfig,
    sequence: str,
    people: People,
    motions: Motions,
    rig: CameraRig,
    detector: DetectorOutput,
    det_id: np.ndarray,
    bias_m: np.ndarray,
    clocks: ViewClocks,
) -> SyntheticScene:
    """The :class:`SyntheticScene`: its canonical tables built from the raw data, and the raw data."""
    return SyntheticScene(
        config=config,
        sequence=sequence,
        detections=_detections_table(sequence, detector, det_id),
        cameras=cameras_to_table(rig, sequence),
        poses3d=_poses3d_table(sequence, people.person_ids, motions.keypoints_world_m),
        associations=_associations_table(sequence, detector, det_id),
        people=_people_table(sequence, people),
        motions=_motions_table(sequence, people, motions),
        rig=rig,
        person_ids=people.person_ids,
        phenotypes=people.phenotypes,
        height_m=people.height_m,
        bone_rotmats_local=motions.bone_rotmats_local,
        root_translation_m=motions.root_translation_m,
        keypoints_world_m=motions.keypoints_world_m,
        activity=motions.activity,
        detector=detector,
        det_id=det_id,
        keypoint_bias_m=bias_m,
        clocks=clocks,
    )


def generate_scene(
    config: SceneConfig,
    body: BodyModel,
    sequence: str = "synthetic",
    progress: ProgressCallback | None = None,
) -> SyntheticScene:
    """Generate the scene that ``config`` describes.

    Args:
        config: the scene config (seed included).
        body: the body model.
        sequence: name written into the ``sequence`` column of every table.
        progress: optional callback ``progress(stage, fraction_done)`` after each stage.

    Returns:
        The :class:`SyntheticScene`.

    Raises:
        ValueError: ``config`` is not a :class:`SceneConfig`, or ``sequence`` is empty.
        humancal.settings.DataRootError: rig ``"h36m"`` without the external data root.
    """
    if not isinstance(config, SceneConfig):
        raise ValueError(f"config must be a SceneConfig, got {type(config).__name__}")
    if not isinstance(sequence, str) or not sequence:
        raise ValueError(f"sequence must be a non-empty string, got {sequence!r}")
    report = progress or (lambda stage, fraction: None)
    # a sixth stream for the out-of-view spells leaves the first five (and older scenes) as they were
    # spawned streams do not depend on how many are spawned: a seventh (the detector's keypoint bias) leaves the
    # first six as they were
    # an eighth (the views' clocks) leaves the first seven as they were; it is drawn from only for unsynced views
    streams = np.random.default_rng(config.seed).spawn(8)
    rng_people, rng_motion, rng_rig, rng_noise, rng_ids, rng_absence, rng_bias, rng_clocks = streams
    started = time.perf_counter()
    clocks = draw_clocks(config, rng_clocks) if config.unsynced else synced_clocks(config)

    people = sample_people(body, config.num_people, rng_people, config.height_range_m)
    report("people", 0.1)
    with torch.no_grad():
        rest = body.rest_skeleton(torch.as_tensor(people.phenotypes, dtype=body.dtype, device=body.device))
    motions = generate_motions(
        body, rest, clocks.reference_frames, config.fps, config.area_size_m, rng_motion, behaviour=config.behaviour
    )
    report("motions", 0.4)
    rig = make_rig(config, rng_rig)
    report("cameras", 0.45)
    hidden = _out_of_view(config, clocks.reference_frames, rng_absence)
    detected_m, bias_m = _detector_keypoints(config, body, rest, motions, rng_bias)
    detector = _simulate_detector(config, clocks, detected_m, people, rig, hidden, rng_noise)
    det_id = _assign_det_ids(detector.frame, detector.view, rng_ids)
    report("detections", 0.8)

    scene = _assemble_scene(config, sequence, people, motions, rig, detector, det_id, bias_m, clocks)
    report("tables", 1.0)
    logger.info(
        "synthetic scene %r: %d people, %d views, %d frames, %d detections in %.2f s",
        sequence,
        config.num_people,
        config.num_views,
        config.num_frames,
        detector.num_detections,
        time.perf_counter() - started,
    )
    return scene
