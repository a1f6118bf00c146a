"""humancal: cameras and 3D body motions of several people from the 2D detections of static, uncalibrated cameras.

The library, in the order the method runs (each subpackage's docstring and ``docs/<stage>.md`` say more):

* :mod:`humancal.captures`, :mod:`humancal.datasets`, :mod:`humancal.formats`, :mod:`humancal.grouping`: the inputs:
  a user's detector output, the packaged datasets (Shelf) and the datasets config, other tools' files.
* :mod:`humancal.sync`: per-view time offsets of unsynchronised videos, from the people's motion.
* :mod:`humancal.lifter`: a root-relative 3D pose for every 2D detection.
* :mod:`humancal.calibration`: the cameras from the people (intrinsics from upright people, extrinsics from aligned
  lifted poses, the bundle adjustment, the per-view checks and repair, the lens).
* :mod:`humancal.association`: who is who across views and over time.
* :mod:`humancal.body`, :mod:`humancal.prior`, :mod:`humancal.fitting`: the anny body model, the VAE motion prior,
  and the bodies fitted to the detections with the cameras refined alongside.
* :mod:`humancal.viewing`: the result as a 3D recording, overlays and pictures.

Shared by the stages: :mod:`humancal.camera` (``Camera``, ``CameraRig``, the projection with lens distortion),
:mod:`humancal.geometry` (rotations, alignment, triangulation), :mod:`humancal.least_squares`, :mod:`humancal.tables` (the canonical tables
and their array views), :mod:`humancal.keypoints` (the 23 canonical keypoints), :mod:`humancal.config` (the base of
every stage's settings), :mod:`humancal.settings` (data and state folders). Training data and test scenes:
:mod:`humancal.mocap`, :mod:`humancal.retarget`, :mod:`humancal.synthetic`. Conventions (frames, units, rotations)
are in ``docs/conventions.md``.
"""
