"""Synthetic multi-person, multi-view scenes with ground truth for everything (``docs/synthetic.md``).

The embedded default dataset of humancal: seeded, reproducible scenes of anny bodies moving through
procedural activities, seen by a random static camera rig through a simulated 2D pose detector.

Example:
    >>> from humancal.body import BodyModel
    >>> from humancal.synthetic import generate_scene, preset
    >>> scene = generate_scene(preset("tiny"), BodyModel(), sequence="tiny")  # doctest: +SKIP
    >>> scene.detections.head()  # doctest: +SKIP
"""

from humancal.synthetic.activities import ACTIVITIES, GESTURES
from humancal.synthetic.config import BEHAVIOURS, RIG_KINDS, SceneConfig
from humancal.synthetic.detector_errors import JOINT_NOISE_WEIGHTS
from humancal.synthetic.detector_noise import DetectorNoise
from humancal.synthetic.motions import Motions, generate_motions
from humancal.synthetic.noise import DetectorOutput, simulate_detections
from humancal.synthetic.people import People, sample_people
from humancal.synthetic.presets import PRESETS, preset, preset_names
from humancal.synthetic.rigs import make_rig
from humancal.synthetic.scene import SyntheticScene, generate_scene

__all__ = [
    "ACTIVITIES",
    "GESTURES",
    "RIG_KINDS",
    "BEHAVIOURS",
    "DetectorNoise",
    "SceneConfig",
    "Motions",
    "generate_motions",
    "JOINT_NOISE_WEIGHTS",
    "DetectorOutput",
    "simulate_detections",
    "People",
    "sample_people",
    "PRESETS",
    "preset",
    "preset_names",
    "make_rig",
    "SyntheticScene",
    "generate_scene",
]
