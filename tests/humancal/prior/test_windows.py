import numpy as np
import pytest
import torch

from humancal.prior.windows import window_layout


@pytest.mark.parametrize("frames,length,overlap", [(1, 64, 8), (64, 64, 8), (65, 64, 8), (300, 64, 8), (901, 48, 0)])
def test_windows_cover_every_frame_once_as_owner(frames, length, overlap):
    layout = window_layout(frames, length, overlap)
    assert layout.starts[0] == 0 and layout.starts[-1] + layout.length == frames
    window_frames = layout.window_frames()
    # each frame's owner window holds it, at the stated offset, and is the window whose centre is nearest
    assert np.array_equal(window_frames[layout.owner_window, layout.owner_offset], np.arange(frames))
    # consecutive windows share at least `overlap` frames (the last may share more, to end at the last frame)
    if layout.num_windows > 1:
        shared = layout.starts[:-1] + layout.length - layout.starts[1:]
        assert (shared >= overlap).all()
        assert len(layout.seam_a) == shared.sum()
        assert np.array_equal(window_frames[layout.seam_a[:, 0], layout.seam_a[:, 1]],
                              window_frames[layout.seam_b[:, 0], layout.seam_b[:, 1]])


def test_split_then_assemble_is_the_identity_and_seams_vanish_on_consistent_windows():
    layout = window_layout(150, 32, 6)
    per_frame = torch.randn(2, 150, 5)
    windowed = layout.split(per_frame)
    assert windowed.shape == (2, layout.num_windows, 32, 5)
    assert torch.equal(layout.assemble(windowed), per_frame)
    assert layout.seam_difference(windowed).abs().max() == 0
    windowed = windowed.clone()
    windowed[:, 1] += 1.0  # window 1 disagrees with its neighbours on the shared frames
    involved = torch.as_tensor((layout.seam_a[:, 0] == 1) | (layout.seam_b[:, 0] == 1))
    expected = involved.to(windowed.dtype)[None, :, None].expand(2, -1, 5)
    assert torch.allclose(layout.seam_difference(windowed).abs(), expected, atol=1e-6)


def test_bad_layouts_are_refused():
    for args in [(0, 64, 8), (100, 3, 0), (100, 16, 8), (100, 16, -1)]:
        with pytest.raises(ValueError, match="window_layout"):
            window_layout(*args)


def test_reconstruction_in_windows_takes_each_frame_from_its_owner_window():
    from humancal.prior import MotionVAE, PriorConfig
    from humancal.prior.windows import reconstruct_in_windows

    torch.manual_seed(0)
    prior = MotionVAE(PriorConfig.tiny()).eval()
    pose6d = torch.randn(2, 70, 21, 6)
    with torch.no_grad():
        out = reconstruct_in_windows(prior, pose6d, 32, 6)
        layout = window_layout(70, 32, 6)
        assert out.shape == pose6d.shape and layout.num_windows == 3
        for t in (0, 25, 26, 40, 69):
            w, offset = layout.owner_window[t], layout.owner_offset[t]
            window = pose6d[:, layout.starts[w]:layout.starts[w] + 32]
            expected = prior.decode(prior.encode(window)[0])[:, offset]
            torch.testing.assert_close(out[:, t], expected)
        # a short motion is one window: the same as decoding it whole
        short = pose6d[:, :20]
        torch.testing.assert_close(reconstruct_in_windows(prior, short, 32, 6), prior.decode(prior.encode(short)[0]))
