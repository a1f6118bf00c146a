"""Bottom-up grouping of OpenPose BODY_25 joint candidates into people by part-affinity scores.

:class:`CandidateFrame` holds one image's candidates and PAF scores; :func:`group_frame` assembles people (greedy
PAF assembly, re-attaching and merging fragments); :func:`group_detections` does it for many images and writes the
canonical ``detections`` table (23 joints). The algorithm is described in ``docs/shelf.md``.
"""

from humancal.grouping.body25 import BODY25_JOINTS, BODY25_LIMBS
from humancal.grouping.candidates import CandidateFrame
from humancal.grouping.canonical import group_detections, people_to_detections
from humancal.grouping.greedy import GroupedPeople, GroupingConfig, group_frame
from humancal.grouping.merge import MergeConfig

__all__ = [
    "BODY25_JOINTS",
    "BODY25_LIMBS",
    "CandidateFrame",
    "GroupedPeople",
    "GroupingConfig",
    "MergeConfig",
    "group_detections",
    "group_frame",
    "people_to_detections",
]
