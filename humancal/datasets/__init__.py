"""The sequences humancal knows, and the readers of the datasets they come from.

* :mod:`humancal.datasets.sequences`: the datasets config (which sequences exist, the users' captures among them).
* :mod:`humancal.datasets.inputs`: one sequence's inputs (and its ground truth, where it exists), whatever its dataset.
* :mod:`humancal.datasets.gt_matching`: which ground-truth person each 2D detection is, where a dataset does not say.
* :mod:`humancal.datasets.shelf`: Shelf as 4D Association ships it (cameras, SHELF15 ground truth, OpenPose
  candidates grouped into people by :mod:`humancal.grouping`); ``docs/shelf.md``.

The package imports none of them: the no-op shortcut of ``humancal update`` reads the datasets config through
:mod:`~humancal.datasets.sequences` and must not pay for the readers' imports (torch, OpenCV).
"""
