"""Mocap readers: BVH and ASF/AMC files to joint world positions (metres, right-handed, Z up, floor z = 0).

See ``docs/mocap.md`` for units, axis conversions and the CMU specifics.
"""

from humancal.mocap.asf import AsfBone, AsfSkeleton, read_asf
from humancal.mocap.asf_amc import CMU_FPS, asf_rest_positions, read_amc
from humancal.mocap.bvh import CMU_DAZ_LEADING_FRAMES, BvhJoint, BvhMotion, bvh_forward_kinematics, parse_bvh, read_bvh
from humancal.mocap.clip import MocapClip, MocapFormatError
from humancal.mocap.duplicates import identical_files
from humancal.mocap.reading import R_ZUP_FROM_YUP, euler_rotmat

__all__ = [
    "MocapClip",
    "MocapFormatError",
    "read_bvh",
    "CMU_DAZ_LEADING_FRAMES",
    "CMU_FPS",
    "parse_bvh",
    "bvh_forward_kinematics",
    "BvhJoint",
    "BvhMotion",
    "read_asf",
    "read_amc",
    "asf_rest_positions",
    "AsfSkeleton",
    "AsfBone",
    "R_ZUP_FROM_YUP",
    "euler_rotmat",
    "identical_files",
]
