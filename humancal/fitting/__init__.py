"""Fitting the people's bodies and motions to the associated detections (the paper's III-E, cameras held).

``body_observations`` gathers what the association found (each person's detections in every view, their
triangulated joints); ``fit_bodies`` fits shape and motion through the motion prior; ``FittedMotions`` is the
result and its ``motions`` table.
"""

from humancal.fitting.config import BodyFitConfig
from humancal.fitting.fit import INITIAL_PHENOTYPES, STAGES, BodyFitResult, fit_bodies
from humancal.fitting.motions import FittedMotions
from humancal.fitting.observations import BodyObservations, FittingInputError, body_observations
from humancal.fitting.windows import WindowLayout, window_layout

__all__ = [
    "BodyFitConfig",
    "BodyFitResult",
    "BodyObservations",
    "FittedMotions",
    "FittingInputError",
    "INITIAL_PHENOTYPES",
    "STAGES",
    "WindowLayout",
    "body_observations",
    "fit_bodies",
    "window_layout",
]
