"""Shared by the motion-prior tests."""

import pytest
import torch


@pytest.fixture(autouse=True)
def _one_thread():
    """Small networks run fastest on one thread (two threads crawl when the other core is busy)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
