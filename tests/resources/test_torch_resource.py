"""The torch resource applies threads and seed for the duration of a block and restores them."""

import pytest
import torch

from resources.torch import TorchResource


def test_threads_and_seed_are_applied_and_restored():
    before_threads = torch.get_num_threads()
    torch.manual_seed(123)
    expected_after = torch.rand(3)  # what the global generator gives next without the block
    torch.manual_seed(123)
    threads = 2 if before_threads != 2 else 1
    with TorchResource(threads=threads, seed=7).applied() as device:
        assert device == torch.device("cpu") and torch.get_num_threads() == threads
        inside = torch.rand(3)
    assert torch.get_num_threads() == before_threads
    assert torch.equal(torch.rand(3), expected_after)  # the generator continues where it was
    with TorchResource(threads=threads, seed=7).applied():
        assert torch.equal(torch.rand(3), inside)  # same seed, same draws


def test_default_threads_leave_torch_setting():
    before = torch.get_num_threads()
    torch.set_num_threads(before + 1)
    try:
        with TorchResource().applied():
            assert torch.get_num_threads() == before + 1
        assert torch.get_num_threads() == before + 1
    finally:
        torch.set_num_threads(before)


def test_restored_when_the_block_raises():
    before = torch.get_num_threads()
    with pytest.raises(RuntimeError, match="boom"):
        with TorchResource(threads=before + 1).applied():
            raise RuntimeError("boom")
    assert torch.get_num_threads() == before


def test_no_silent_device_fallback():
    with pytest.raises(ValueError, match="is not a torch device"):
        TorchResource(device="gpu0").torch_device()
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="CUDA is not available"):
            TorchResource(device="cuda").torch_device()
    with pytest.raises(ValueError, match="threads=0 must be >= 1"):
        with TorchResource(threads=0).applied():
            pass
