"""The canonical tables and their array views.

* :mod:`humancal.tables.schemas`: one declared pyarrow schema per table, and their validation.
* :mod:`humancal.tables.plausibility`: plausibility checks of the tables (the pipeline's asset checks, the readers).
* :mod:`humancal.tables.detections`, :mod:`humancal.tables.poses`, :mod:`humancal.tables.associations`: dense array
  views of the long ``detections``, ``poses3d`` and ``associations`` tables.
* :mod:`humancal.tables.pivot`: the building blocks that pivot a long table (one row per joint) into dense arrays.
"""
