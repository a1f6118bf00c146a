"""Per-stage settings as Dagster ``Config`` classes, shown and editable in the UI's launchpad.

Each class mirrors one settings dataclass of the library field by field: the same names, the same defaults (taken
from the dataclass itself, so they cannot drift) and the same descriptions (the dataclass docstring's
``Attributes`` entries), with ``to_library()`` converting in one line. A pipeline may choose a different default
for a field; those choices are listed in ``PIPELINE_DEFAULTS`` of each class and nowhere else.
"""

from __future__ import annotations

import dataclasses
import inspect
import re
from typing import Any, ClassVar, Literal

import dagster as dg
from pydantic import Field

from humancal.association import AffinityConfig, SmoothingConfig, TrackingConfig
from humancal.calibration import ExtrinsicsConfig, IntrinsicsConfig
from humancal.fitting import BodyFitConfig

__all__ = ["IntrinsicsSettings", "ExtrinsicsSettings", "AssociationSettings", "BodyFitSettings", "attribute_docs",
           "library_field"]


def attribute_docs(cls: type) -> dict[str, str]:
    """The ``Attributes:`` entries of a Google-style class docstring, by attribute name.

    An entry may name several attributes (``"plumb_top, plumb_bottom: ..."``); continuation lines are joined.
    """
    doc = inspect.getdoc(cls) or ""
    section = doc.split("Attributes:", 1)[1] if "Attributes:" in doc else ""
    entries: dict[str, str] = {}
    names: list[str] = []
    for line in section.splitlines():
        if line and not line.startswith(" "):  # the next section
            break
        match = re.match(r"^ {4}([A-Za-z_][\w, ]*):\s*(.*)$", line)
        if match:
            names = [n.strip() for n in match.group(1).split(",")]
            for name in names:
                entries[name] = match.group(2).strip()
        elif line.strip() and names:
            for name in names:
                entries[name] += " " + line.strip()
    return entries


def library_field(dataclass_type: type, name: str, default: Any = dataclasses.MISSING) -> Any:
    """A pydantic field with the dataclass field's default (tuples as lists) and docstring description."""
    if default is dataclasses.MISSING:
        default = {f.name: f.default for f in dataclasses.fields(dataclass_type)}[name]
    if isinstance(default, tuple):
        default = list(default)
    return Field(default=default, description=attribute_docs(dataclass_type)[name])


def _to_library(settings: dg.Config, dataclass_type: type):
    values = settings.model_dump()
    types = {f.name: f.default for f in dataclasses.fields(dataclass_type)}
    return dataclass_type(**{k: tuple(v) if isinstance(types[k], tuple) else v for k, v in values.items()})


_I = IntrinsicsConfig


class IntrinsicsSettings(dg.Config):
    """Settings of the ``intrinsics`` asset (:class:`humancal.calibration.IntrinsicsConfig`)."""

    PIPELINE_DEFAULTS: ClassVar[dict[str, Any]] = {"missing_upright": "defer"}
    """A view without upright people is deferred to the multi-view focal recovery of the extrinsics step."""

    upright_threshold: float = library_field(_I, "upright_threshold")
    plumb_top: str = library_field(_I, "plumb_top")
    plumb_bottom: str = library_field(_I, "plumb_bottom")
    min_joint_score: float = library_field(_I, "min_joint_score")
    min_line_length_px: float = library_field(_I, "min_line_length_px")
    angle_threshold_deg: float = library_field(_I, "angle_threshold_deg")
    ransac_iterations: int = library_field(_I, "ransac_iterations")
    max_candidates: int = library_field(_I, "max_candidates")
    square_pixels: bool = library_field(_I, "square_pixels")
    focal_range_rel: list[float] = library_field(_I, "focal_range_rel")
    max_focal_rel_uncertainty: float = library_field(_I, "max_focal_rel_uncertainty")
    lean_std_deg: float = library_field(_I, "lean_std_deg")
    height_rel_std: float = library_field(_I, "height_rel_std")
    min_inliers: int = library_field(_I, "min_inliers")
    missing_upright: Literal["raise", "defer"] = library_field(_I, "missing_upright", "defer")
    seed: int = library_field(_I, "seed")

    def to_library(self) -> IntrinsicsConfig:
        """The library's settings (validated there: a bad value raises ``ValueError`` naming the field)."""
        return _to_library(self, IntrinsicsConfig)


_E = ExtrinsicsConfig


class ExtrinsicsSettings(dg.Config):
    """Settings of the ``extrinsics`` asset (:class:`humancal.calibration.ExtrinsicsConfig`)."""

    PIPELINE_DEFAULTS: ClassVar[dict[str, Any]] = {}

    rotation_threshold_deg: float = library_field(_E, "rotation_threshold_deg")
    max_pose_error_m: float = library_field(_E, "max_pose_error_m")
    max_frames_per_pair: int = library_field(_E, "max_frames_per_pair")
    max_pair_hypotheses: int = library_field(_E, "max_pair_hypotheses")
    min_pair_support: int = library_field(_E, "min_pair_support")
    linear_iterations: int = library_field(_E, "linear_iterations")
    linear_max_rel_std: float = library_field(_E, "linear_max_rel_std")
    single_view_min_rel_std: float = library_field(_E, "single_view_min_rel_std")
    focal_range_rel: list[float] = library_field(_E, "focal_range_rel")
    max_groups: int = library_field(_E, "max_groups")
    shape_std_m: float = library_field(_E, "shape_std_m")
    person_scale_std: float | None = library_field(_E, "person_scale_std")
    bundle_iterations: int = library_field(_E, "bundle_iterations")
    max_focal_rel_std: float = library_field(_E, "max_focal_rel_std")
    square_pixels: bool = library_field(_E, "square_pixels")
    align_floor: bool = library_field(_E, "align_floor")
    upright_threshold: float = library_field(_E, "upright_threshold")
    seed: int = library_field(_E, "seed")
    fov_range_deg: list[float] = library_field(_E, "fov_range_deg")
    blind_start_fov_deg: list[float] = library_field(_E, "blind_start_fov_deg")
    blind_start_iterations: int = library_field(_E, "blind_start_iterations")
    mismatch_threshold_sigma: float = library_field(_E, "mismatch_threshold_sigma")
    mismatch_max_fraction: float = library_field(_E, "mismatch_max_fraction")
    mismatch_rounds: int = library_field(_E, "mismatch_rounds")
    regroup_max_frames: int = library_field(_E, "regroup_max_frames")
    regroup_min_gain: float = library_field(_E, "regroup_min_gain")
    repair_views: bool = library_field(_E, "repair_views")
    scale_from_limbs: bool = library_field(_E, "scale_from_limbs")
    max_loo_sigma: float = library_field(_E, "max_loo_sigma")
    min_explained_fraction: float = library_field(_E, "min_explained_fraction")
    lens_models: list[str] = library_field(_E, "lens_models")
    principal_point: str = library_field(_E, "principal_point")
    lens_min_gain: float = library_field(_E, "lens_min_gain")
    lens_max_k1_std: float = library_field(_E, "lens_max_k1_std")
    lens_min_k1_sigma: float = library_field(_E, "lens_min_k1_sigma")

    def to_library(self) -> ExtrinsicsConfig:
        """The library's settings (validated there: a bad value raises ``ValueError`` naming the field)."""
        return _to_library(self, ExtrinsicsConfig)


_T = TrackingConfig
_A = AffinityConfig
_S = SmoothingConfig


class AssociationSettings(dg.Config):
    """Settings of the ``associations`` asset (:class:`humancal.association.TrackingConfig`, its scalar fields,
    the two weights of its :class:`~humancal.association.AffinityConfig` and its
    :class:`~humancal.association.SmoothingConfig` as ``smoothing*``; the other affinity and matching settings
    keep the library's defaults)."""

    PIPELINE_DEFAULTS: ClassVar[dict[str, Any]] = {}

    geometric_weight: float = library_field(_A, "geometric_weight")
    pose_weight: float = library_field(_A, "pose_weight")
    match_threshold: float = library_field(_T, "match_threshold")
    temporal: bool = library_field(_T, "temporal")
    fps: float = library_field(_T, "fps")
    reid_window_s: float = library_field(_T, "reid_window_s")
    assign_distance_m: float = library_field(_T, "assign_distance_m")
    reid_speed_mps: float = library_field(_T, "reid_speed_mps")
    bone_tolerance: float = library_field(_T, "bone_tolerance")
    min_views: int = library_field(_T, "min_views")
    min_track_s: float = library_field(_T, "min_track_s")
    stitch_window_s: float = library_field(_T, "stitch_window_s")
    outlier_threshold_px: float = library_field(_T, "outlier_threshold_px")
    num_people: int | None = library_field(_T, "num_people")
    smoothing: bool = library_field(_S, "enabled")
    smoothing_scale_px: float = library_field(_S, "scale_px")
    smoothing_acceleration_mps2: float = library_field(_S, "acceleration_mps2")
    smoothing_max_fill_frames: int = library_field(_S, "max_fill_frames")

    def to_library(self) -> TrackingConfig:
        """The library's settings (validated there: a bad value raises ``ValueError`` naming the field)."""
        values = self.model_dump()
        affinity = AffinityConfig(geometric_weight=values.pop("geometric_weight"),
                                  pose_weight=values.pop("pose_weight"))
        smoothing = SmoothingConfig(enabled=values.pop("smoothing"), scale_px=values.pop("smoothing_scale_px"),
                                    acceleration_mps2=values.pop("smoothing_acceleration_mps2"),
                                    max_fill_frames=values.pop("smoothing_max_fill_frames"))
        return TrackingConfig(affinity=affinity, smoothing=smoothing, **values)


_B = BodyFitConfig


class BodyFitSettings(dg.Config):
    """Settings of the body fit (``fitted_motions`` and ``refined_cameras``; :class:`humancal.fitting.BodyFitConfig`);
    the comparison fits of ``method_tables`` use the same settings."""

    PIPELINE_DEFAULTS: ClassVar[dict[str, Any]] = {}

    noise_px: float = library_field(_B, "noise_px")
    robust_scale_px: float = library_field(_B, "robust_scale_px")
    noise_3d_m: float = library_field(_B, "noise_3d_m")
    robust_scale_3d_m: float = library_field(_B, "robust_scale_3d_m")
    weight_latent: float = library_field(_B, "weight_latent")
    weight_local_linear: float = library_field(_B, "weight_local_linear")
    weight_local_linear_3d: float = library_field(_B, "weight_local_linear_3d")
    weight_rest: float = library_field(_B, "weight_rest")
    weight_shape: float = library_field(_B, "weight_shape")
    weight_root_smooth: float = library_field(_B, "weight_root_smooth")
    root_smooth_scale_m: float = library_field(_B, "root_smooth_scale_m")
    weight_seam: float = library_field(_B, "weight_seam")
    window_frames: int = library_field(_B, "window_frames")
    window_overlap: int = library_field(_B, "window_overlap")
    latent_start: str = library_field(_B, "latent_start")
    iterations_3d: int = library_field(_B, "iterations_3d")
    half_rate_fraction_3d: float = library_field(_B, "half_rate_fraction_3d")
    learning_rate_3d: float = library_field(_B, "learning_rate_3d")
    iterations_global: int = library_field(_B, "iterations_global")
    iterations_body: int = library_field(_B, "iterations_body")
    fit_shape: bool = library_field(_B, "fit_shape")
    cameras: str = library_field(_B, "cameras")
    refine_k1: bool = library_field(_B, "refine_k1")
    bundle_start: bool = library_field(_B, "bundle_start")
    rounds: int = library_field(_B, "rounds")
    round_stop_px: float = library_field(_B, "round_stop_px")
    iterations_cameras: int = library_field(_B, "iterations_cameras")
    weight_camera_prior: float = library_field(_B, "weight_camera_prior")
    camera_prior_scale_m: float = library_field(_B, "camera_prior_scale_m")
    weight_interpenetration: float = library_field(_B, "weight_interpenetration")
    contact_scale_m: float = library_field(_B, "contact_scale_m")

    def to_library(self) -> BodyFitConfig:
        """The library's settings (validated there: a bad value raises ``ValueError`` naming the field)."""
        return _to_library(self, BodyFitConfig)
