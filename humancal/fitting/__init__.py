"""Fitting the people's bodies and motions, and refining the cameras with them (the paper's III-E).

``body_observations`` gathers what the association found (each person's detections in every view, their
triangulated joints); ``fit_bodies`` fits shape and motion through the motion prior and, unless told to hold them,
refines the cameras together with the people (``CameraVariables``); ``FittedMotions`` is the result and its
``motions`` table. ``bundle_adjust_on_joints`` refines the cameras on the triangulated joints alone: where moving cameras
start (``BodyFitConfig.bundle_start``), and the "separate" baseline.
"""

from humancal.fitting.cameras import CAMERA_REGIMES, CameraVariables
from humancal.fitting.config import BodyFitConfig
from humancal.fitting.fit import INITIAL_PHENOTYPES, STAGES, BodyFitResult, fit_bodies
from humancal.fitting.joint_bundle import BundleResult, bundle_adjust_on_joints
from humancal.fitting.motions import FittedMotions
from humancal.fitting.observations import BodyObservations, FittingInputError, body_observations

__all__ = [
    "BodyFitConfig",
    "BundleResult",
    "CAMERA_REGIMES",
    "CameraVariables",
    "BodyFitResult",
    "BodyObservations",
    "FittedMotions",
    "FittingInputError",
    "INITIAL_PHENOTYPES",
    "STAGES",
    "body_observations",
    "bundle_adjust_on_joints",
    "fit_bodies",
]
