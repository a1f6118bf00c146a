"""Dataset readers: each reads a dataset's own files and returns the canonical tables and conventions.

* :mod:`humancal.datasets.shelf`: Shelf as 4D Association ships it (cameras, SHELF15 ground truth, OpenPose
  candidates grouped into people by :mod:`humancal.grouping`); ``docs/shelf.md``.
"""

from humancal.datasets.shelf import ShelfSequence, load_shelf

__all__ = ["ShelfSequence", "load_shelf"]
