"""The docstring examples of the library run as doctests: every module of ``humancal`` and ``evaluation`` whose
docstrings hold an example (``>>>``) is run through :mod:`doctest` (examples marked ``+SKIP`` need data or minutes:
they are read, not run)."""

from __future__ import annotations

import doctest
import importlib
import importlib.util
import pkgutil
from pathlib import Path

import pytest

import evaluation
import humancal

FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE


def _modules_with_examples() -> list[str]:
    names = []
    for package in (humancal, evaluation):
        for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
            origin = importlib.util.find_spec(info.name).origin
            if origin and origin.endswith(".py") and ">>>" in Path(origin).read_text():
                names.append(info.name)
    return sorted(names)


MODULES = _modules_with_examples()


@pytest.mark.parametrize("name", MODULES)
def test_the_examples_of_each_module_run(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=FLAGS, verbose=False)
    assert result.failed == 0, f"{name}: {result.failed} of {result.attempted} examples failed (run with -s to see)"


def test_the_geometry_and_cameras_are_shown_by_running_examples():
    """Not only skipped ones: the modules a newcomer reads first carry examples that run."""
    ran = {name: doctest.testmod(importlib.import_module(name), optionflags=FLAGS).attempted for name in
           ("humancal.camera", "humancal.geometry.rotations", "humancal.geometry.alignment",
            "humancal.geometry.triangulation", "humancal.least_squares")}
    assert all(count >= 3 for count in ran.values()), ran
