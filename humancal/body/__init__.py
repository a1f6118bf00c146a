"""Body model layer: anny with an exact fast keypoint path (``docs/body_model.md``).

Shape is per person (:meth:`BodyModel.rest_skeleton`), pose per frame (:meth:`BodyModel.keypoints`).
"""

from humancal.body.bones import POSED_BONE_NAMES, POSED_BONE_SPEC
from humancal.body.model import PHENOTYPE_NAMES, BodyModel
from humancal.body.rest import RestSkeleton

__all__ = ["BodyModel", "RestSkeleton", "PHENOTYPE_NAMES", "POSED_BONE_NAMES", "POSED_BONE_SPEC"]
