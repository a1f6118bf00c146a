"""Shared fixtures: the body model is built once per test session (anny's cache lives in the state dir)."""

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
os.environ.setdefault("ANNY_CACHE_DIR", str(REPO / ".humancal" / "cache" / "anny"))
if "PYTEST_XDIST_WORKER" in os.environ:
    # Parallel workers (`make test` runs one per core): one compute thread each, so they do not fight over the cores.
    os.environ.setdefault("OMP_NUM_THREADS", "1")


@pytest.fixture(scope="session")
def body_model():
    from humancal.body import BodyModel

    return BodyModel()
