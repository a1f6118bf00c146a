"""Mocap on the body model: retarget joint positions (CMU Daz BVH) onto anny (``docs/retarget.md``).

Per subject one shape (phenotypes and correspondence offsets, :func:`fit_subject`), per frame one pose
(22 local-ref bone rotations and the root translation, :func:`retarget_clip`), by position-based inverse
kinematics through a stated joint correspondence (:data:`DAZ_CMU_LINKS`).

```python
from humancal.body import BodyModel
from humancal.retarget import RetargetConfig, retarget_clips, clips_to_motions_table, residual_summary

body = BodyModel()
clips = retarget_clips(paths_of_bvh_files, body, RetargetConfig())
motions = clips_to_motions_table(clips)          # the canonical "motions" table
print(residual_summary(clips))                   # per clip: median / p95 / max residual, mm
```
"""

from humancal.retarget.clips import RetargetedClip, retarget_clip, retarget_clips
from humancal.retarget.config import RetargetConfig
from humancal.retarget.correspondence import DAZ_CMU_LINKS, JointLink, ResolvedLinks, mocap_targets_m, resolve_links
from humancal.retarget.plot import plot_retarget
from humancal.retarget.shape import SubjectFit, fit_subject, fit_subject_phenotypes
from humancal.retarget.tables import (
    clips_to_motions_table,
    motions_table_to_clips,
    pooled_residual_mm,
    residual_summary,
)

__all__ = [
    "RetargetConfig",
    "RetargetedClip",
    "SubjectFit",
    "JointLink",
    "ResolvedLinks",
    "DAZ_CMU_LINKS",
    "resolve_links",
    "mocap_targets_m",
    "fit_subject",
    "fit_subject_phenotypes",
    "retarget_clip",
    "retarget_clips",
    "clips_to_motions_table",
    "motions_table_to_clips",
    "residual_summary",
    "pooled_residual_mm",
    "plot_retarget",
]
