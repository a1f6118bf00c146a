"""Geometry shared by the stages, in the conventions of ``docs/conventions.md`` (the projection through a camera
is :mod:`humancal.camera.projection`).

* :mod:`humancal.geometry.rotations`: rotation conversions, angles and distances (the only place they are computed).
* :mod:`humancal.geometry.alignment`: similarity and rigid alignment of point sets (Umeyama).
* :mod:`humancal.geometry.triangulation`: multi-view triangulation with known cameras.
* :mod:`humancal.geometry.pose_errors`: MPJPE and PA-MPJPE.
"""
