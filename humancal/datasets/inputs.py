"""Load the inputs (and the ground truth, where it exists) of one sequence, whatever its dataset."""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from humancal.datasets.sequences import SequenceSpec
from humancal.settings import DATA_DIR_ENV, DataRootError
from humancal.tables.schemas import empty_table, validate_table

__all__ = ["DEFAULT_FPS", "SequenceInputs", "body_fit_regime", "capture_footage", "load_sequence_inputs", "sequence_fps",
           "sequence_principal_points"]

DEFAULT_FPS = 30.0
"""The frame rate assumed where a sequence does not say (a capture without ``fps``; Shelf)."""

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SequenceInputs:
    """Everything a sequence brings, as canonical tables.

    Attributes:
        detections: 2D detections (the method's only input besides ``views``).
        views: image size per view.
        gt_cameras: ground-truth cameras (evaluation only).
        gt_poses3d: ground-truth 3D joints (canonical names for synthetic data, the dataset's own
            skeleton otherwise; evaluation only).
        gt_associations: ground-truth identity of each detection, -1 for false positives (evaluation
            and the identified baselines only).
        gt_people: ground-truth body shape per person (empty where unknown).
        gt_motions: ground-truth body-model motions (synthetic scenes: the anny parameters the people were made
            with; empty where unknown; evaluation only).
        known_cameras: the cameras a user's capture brings for the method to use (some views or all; empty: the
            cameras are calibrated from the people).
        detections_notes: what was done to the detections on loading, as text for the detections' metadata (an
            unsynchronised capture: its views' time offsets); empty when nothing was.
    """

    detections: pd.DataFrame
    views: pd.DataFrame
    gt_cameras: pd.DataFrame
    gt_poses3d: pd.DataFrame
    gt_associations: pd.DataFrame
    gt_people: pd.DataFrame
    gt_motions: pd.DataFrame = field(default_factory=lambda: empty_table("motions"))
    known_cameras: pd.DataFrame = field(default_factory=lambda: empty_table("cameras"))
    detections_notes: dict[str, str] = field(default_factory=dict)


def sequence_fps(spec: SequenceSpec) -> tuple[float, str]:
    """The frame rate of a sequence, frames per second, and where it comes from: its datasets entry's ``fps``
    option (a capture whose ``view_fps`` names its first view: that view's, the clock its views are put on), a
    synthetic preset's rate, or :data:`DEFAULT_FPS` (Shelf's files do not state one)."""
    view_fps = spec.options.get("view_fps")
    if spec.kind == "capture" and isinstance(view_fps, dict) and spec.options.get("views"):
        first = Path(str(spec.options["views"][0]))
        name = first.stem if spec.options.get("format") == "coco" else first.name
        if name in view_fps:
            return float(view_fps[name]), f"the capture options of {spec.key} (view_fps of its first view, {name})"
    if spec.options.get("fps") is not None:
        return float(spec.options["fps"]), f"the {spec.kind} options of {spec.key}"
    if spec.kind == "synthetic":
        from humancal.synthetic import preset

        options = dict(spec.options)
        name = options.pop("preset", "demo")
        return float(preset(name, **options).fps), f"synthetic preset {name!r}"
    return DEFAULT_FPS, f"default: {spec.key} states no frame rate"


def capture_footage(spec: SequenceSpec, view_names: list[str]) -> list | None:
    """The footage a capture was registered with (its ``videos`` option), per view of ``view_names`` (the stored
    views: dropped views are not among them), each on the capture's clock (a view of another frame rate or time
    offset reads its own frames: :class:`humancal.viewing.footage.Footage` ``frame_scale``, ``frame_offset``); None
    when the sequence has no footage.

    Raises:
        FileNotFoundError, humancal.formats.FormatError: a video or image folder that is gone or unreadable.
    """
    if spec.kind != "capture" or not spec.options.get("videos"):
        return None
    import dataclasses

    from humancal.captures import CaptureConfig, view_name
    from humancal.sync.capture import DEFAULT_SYNC_FPS
    from humancal.viewing.footage import open_footage

    config = CaptureConfig.from_options(spec.options, spec.base_dir)
    names = [view_name(p, v) for v, p in enumerate(config.views)]
    rates = dict(config.view_fps)
    offsets = dict(config.time_offsets_s)
    default_fps = DEFAULT_SYNC_FPS if config.fps is None else float(config.fps)
    fps0, offset0 = rates.get(names[0], default_fps), offsets.get(names[0], 0.0)
    by_name = dict(zip(names, config.videos or ()))
    out = []
    for name in view_names:
        if name not in by_name:
            out.append(None)
            continue
        fps = rates.get(name, default_fps)
        out.append(dataclasses.replace(open_footage(by_name[name]), frame_scale=fps / fps0,
                                       frame_offset=(offset0 - offsets.get(name, 0.0)) * fps))
    return out


def sequence_principal_points(spec: SequenceSpec, image_sizes_px: list[tuple[int, int]]
                              ) -> list[tuple[float, float]] | None:
    """The known principal points of a sequence (its datasets entry's ``principal_point`` option: ``[cx, cy]`` for
    every view or one per view, pixels), or None: the calibration then puts them at the image centres.

    Raises:
        ValueError: a malformed option (the message names the datasets file, the partition and the view).
    """
    value = spec.options.get("principal_point")
    if value is None:
        return None
    from humancal.captures import principal_points_option

    where = f"{spec.source or 'the datasets config'}: {spec.key}: principal_point"
    return list(principal_points_option(value, image_sizes_px, where))


def body_fit_regime(spec: SequenceSpec, default: str) -> str:
    """The body fit's camera regime for a sequence: ``"fixed"`` for a capture whose cameras are all known (its
    ``cameras`` option names no ``views``, or all of them) unless the option says ``refine``; else ``default``."""
    cameras = spec.options.get("cameras")
    if spec.kind != "capture" or not isinstance(cameras, dict) or cameras.get("refine", False):
        return default
    named = cameras.get("views")
    dropped = set(spec.options.get("drop_views", []))
    views = [v for v in spec.options.get("views", []) if not {Path(str(v)).name, Path(str(v)).stem} & dropped]
    return "fixed" if named is None or len(named) >= len(views) else default


def views_from_cameras(cameras: pd.DataFrame) -> pd.DataFrame:
    """The ``views`` table of a ``cameras`` table (view names ``view_<n>``)."""
    views = cameras[["sequence", "view", "width_px", "height_px"]].copy()
    views.insert(2, "name", [f"view_{v}" for v in views["view"]])
    return validate_table(views, "views")


def load_sequence_inputs(spec: SequenceSpec, body_model: Callable[[], object], data_root: Path | None) -> SequenceInputs:
    """Load or generate the inputs of ``spec``.

    Args:
        spec: the sequence.
        body_model: returns the ``humancal.body.BodyModel`` (only called for synthetic data).
        data_root: external data root (``humancal.settings.data_root()``); None when there is none.

    Raises:
        humancal.settings.DataRootError: the sequence needs external data that is not there.
        ValueError: the sequence options are invalid (message names the option).
    """
    if spec.kind == "synthetic":
        return _load_synthetic(spec, body_model())
    if spec.kind == "shelf":
        return _load_shelf(spec, _data_folder(spec, data_root))
    if spec.kind == "capture":
        return _load_capture(spec)
    raise ValueError(f"sequence {spec.key}: no loader for dataset kind {spec.kind!r}")


def _load_synthetic(spec: SequenceSpec, body) -> SequenceInputs:
    from humancal.synthetic import generate_scene, preset

    options = dict(spec.options)
    name = options.pop("preset", "demo")
    config = preset(name, **options)
    log.info("generating synthetic scene %s (preset %s)", spec.key, name)
    scene = generate_scene(config, body, sequence=spec.sequence)
    return SequenceInputs(
        detections=scene.detections,
        views=views_from_cameras(scene.cameras),
        gt_cameras=scene.cameras,
        gt_poses3d=scene.poses3d,
        gt_associations=scene.associations,
        gt_people=scene.people,
        gt_motions=scene.motions,
    )


def _load_capture(spec: SequenceSpec) -> SequenceInputs:
    """A user's capture: detections and views; known cameras (used by the method) and reference cameras (the
    ground-truth cameras) when given; no other ground truth."""
    from humancal.captures import CaptureConfig, load_capture

    try:
        config = CaptureConfig.from_options(spec.options, spec.base_dir)
    except ValueError as err:
        raise ValueError(f"sequence {spec.key} ({spec.source}): {err}") from None
    capture = load_capture(config, spec.sequence)
    for line in capture.summary.lines():
        log.info("%s:%s", spec.key, line)
    return SequenceInputs(
        detections=capture.detections,
        views=capture.views,
        gt_cameras=capture.gt_cameras,
        gt_poses3d=empty_table("poses3d"),
        gt_associations=empty_table("associations"),
        gt_people=empty_table("people"),
        known_cameras=capture.known_cameras,
        detections_notes=(capture.summary.sync.metadata(capture.summary.names)
                          if capture.summary.sync is not None else {}),
    )


def _data_folder(spec: SequenceSpec, data_root: Path | None) -> Path:
    folder = spec.data_folder
    if data_root is None:
        raise DataRootError(f"sequence {spec.key} needs external data: set {DATA_DIR_ENV} to the folder holding {folder}/")
    path = data_root / folder
    if not path.is_dir():
        raise DataRootError(f"sequence {spec.key}: {path} does not exist (data root from {DATA_DIR_ENV})")
    return path


def _load_shelf(spec: SequenceSpec, folder: Path) -> SequenceInputs:
    from humancal.camera import cameras_to_table
    from humancal.datasets.gt_matching import match_ground_truth
    from humancal.datasets.shelf import load_shelf

    shelf = load_shelf(folder)
    cameras = cameras_to_table(shelf.cameras, spec.sequence)
    detections = shelf.detections.assign(sequence=spec.sequence)
    gt_poses = shelf.gt_poses.assign(sequence=spec.sequence)
    # Shelf does not say who each detection is; for evaluation and the identified baselines, a detection
    # is the ground-truth person it matches (one-to-one per view and frame, mean joint error under 5 % of
    # the image diagonal), otherwise -1.
    matched = match_ground_truth(detections, gt_poses, shelf.cameras).person_views
    matched = matched[matched["det_id"] >= 0]
    ids = detections[["sequence", "frame", "view", "det_id"]].drop_duplicates()
    ids = ids.merge(matched[["frame", "view", "det_id", "person_id"]], on=["frame", "view", "det_id"], how="left")
    ids["person_id"] = ids["person_id"].fillna(-1).astype("int32")
    return SequenceInputs(
        detections=detections,
        views=views_from_cameras(cameras),
        gt_cameras=cameras,
        gt_poses3d=gt_poses,
        gt_associations=validate_table(ids, "associations"),
        gt_people=empty_table("people"),
    )
