"""The sphere-proxy interpenetration penalty on real anny keypoints (the average adult of the fit)."""

import numpy as np
import pytest
import torch

from evaluation.contact_metrics import skin_vertices
from humancal.fitting import INITIAL_PHENOTYPES
from humancal.fitting.contact import (SEGMENT_RADII_M, SPHERE_SEGMENTS, body_spheres, interpenetration,
                                      measure_segment_radii)


@pytest.fixture(scope="module")
def average_body(body_model):
    """(23, 3) keypoints and (V, 3) vertices of the average adult standing in the reference pose, metres."""
    phenotypes = torch.tensor([INITIAL_PHENOTYPES], dtype=body_model.dtype)
    translation = torch.zeros(1, 1, 3, dtype=body_model.dtype)
    with torch.no_grad():
        out = body_model.reference_forward(phenotypes, body_model.identity_pose(1, 1), translation)
    return out["keypoints"][0, 0].double(), out["vertices"][0, 0].double().numpy()


def _pair(keypoints, shift_m, frames=1):
    """(2, frames, 23, 3): the body and a copy of it moved by ``shift_m`` (3,)."""
    shift = torch.as_tensor(shift_m, dtype=keypoints.dtype)
    return torch.stack([keypoints, keypoints + shift])[:, None].expand(2, frames, -1, -1).clone()


def _brute_force(keypoints, present):
    """The penalty over every pair of people, frame and sphere pair, with no pruning."""
    centres, radii = body_spheres(keypoints)
    total = keypoints.new_zeros(())
    P, T = present.shape
    for p in range(P):
        for q in range(p + 1, P):
            d = torch.cdist(centres[p], centres[q], compute_mode="donot_use_mm_for_euclid_dist")  # (T, S, S)
            both = (present[p] & present[q]).to(keypoints.dtype)[:, None, None]
            total = total + (torch.relu(radii[:, None] + radii[None, :] - d) ** 2 * both).sum()
    return total / T


@pytest.fixture
def one_thread():
    """Hundreds of tiny steps: one thread avoids the threads' start-up cost on a busy machine."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def test_overlapping_bodies_are_pushed_apart(average_body, one_thread):
    keypoints, _ = average_body
    shift = torch.tensor([0.1, 0.0, 0.0], dtype=torch.float64, requires_grad=True)
    optimizer = torch.optim.Adam([shift], lr=0.01)
    present = torch.ones(2, 1, dtype=torch.bool)
    start = float(interpenetration(_pair(keypoints, shift.detach()), present))
    assert start > 1e-3
    for _ in range(300):
        optimizer.zero_grad()
        base = keypoints[None, None]
        loss = interpenetration(torch.cat([base, base + shift]), present)
        loss.backward()
        optimizer.step()
    end = float(interpenetration(_pair(keypoints, shift.detach()), present))
    assert end < 1e-6 * start, (start, end)
    # side by side (the body is about 0.5 m wide at the elbows of its reference pose), not through each other
    # moved apart until the proxies no longer touch: more than a torso sphere's diameter (0.18 m) from the start
    assert float(shift.detach().norm()) > 0.25, shift


def test_bodies_apart_cost_exactly_nothing(average_body):
    keypoints, _ = average_body
    pair = _pair(keypoints, [2.0, 0.0, 0.0], frames=3).requires_grad_()
    loss = interpenetration(pair, torch.ones(2, 3, dtype=torch.bool))
    loss.backward()
    assert loss.item() == 0.0
    assert torch.count_nonzero(pair.grad) == 0


def test_one_person_costs_nothing(average_body):
    keypoints, _ = average_body
    one = keypoints[None, None].expand(1, 4, -1, -1)
    assert float(interpenetration(one, torch.ones(1, 4, dtype=torch.bool))) == 0.0


def test_absent_frames_contribute_nothing(average_body):
    keypoints, _ = average_body
    pair = _pair(keypoints, [0.1, 0.05, 0.0], frames=2).requires_grad_()
    both = torch.ones(2, 2, dtype=torch.bool)
    one_absent = both.clone()
    one_absent[1, 1] = False
    full = interpenetration(pair, both)
    half = interpenetration(pair, one_absent)
    half.backward()
    assert full.item() > 0 and half.item() == pytest.approx(full.item() / 2, rel=1e-12)
    assert torch.count_nonzero(pair.grad[:, 1]) == 0 and torch.count_nonzero(pair.grad[:, 0]) > 0


def test_the_pruning_is_exact(average_body):
    """Random placements and headings of four people: the pruned penalty and gradient equal the brute force."""
    keypoints, _ = average_body
    rng = np.random.default_rng(0)
    P, T = 4, 12
    angle = rng.uniform(-np.pi, np.pi, (P, T))
    rotation = torch.zeros(P, T, 3, 3, dtype=torch.float64)
    rotation[..., 0, 0], rotation[..., 0, 1] = torch.tensor(np.cos(angle)), torch.tensor(-np.sin(angle))
    rotation[..., 1, 0], rotation[..., 1, 1] = torch.tensor(np.sin(angle)), torch.tensor(np.cos(angle))
    rotation[..., 2, 2] = 1.0
    offset = torch.tensor(rng.uniform(-0.6, 0.6, (P, T, 3)) * [1, 1, 0.1])
    people = (torch.einsum("ptij,kj->ptki", rotation, keypoints) + offset[:, :, None]).requires_grad_()
    present = torch.tensor(rng.random((P, T)) < 0.8)
    fast = interpenetration(people, present)
    (grad_fast,) = torch.autograd.grad(fast, people)
    slow = _brute_force(people, present)
    (grad_slow,) = torch.autograd.grad(slow, people)
    assert slow.item() > 0
    torch.testing.assert_close(fast, slow, rtol=1e-10, atol=1e-12)
    torch.testing.assert_close(grad_fast, grad_slow, rtol=1e-8, atol=1e-10)


def test_radii_are_measured_on_the_average_body(body_model, average_body):
    keypoints, vertices = average_body
    skin = skin_vertices(body_model.faces.numpy(), body_model.num_vertices)
    measured = measure_segment_radii(vertices[skin], keypoints.numpy())
    assert set(measured) == set(SEGMENT_RADII_M)
    for segment, radius in SEGMENT_RADII_M.items():
        assert measured[segment] == pytest.approx(radius, abs=0.002), segment
    # the chains have no gaps: consecutive spheres of a segment at most about one radius apart
    centres, radii = body_spheres(keypoints)
    segments = np.array(SPHERE_SEGMENTS)
    for segment in ("upper_arm", "forearm", "hand", "thigh", "shin", "foot"):
        chain = centres[np.flatnonzero(segments == segment)].reshape(2, -1, 3)  # left, right
        step = (chain[:, 1:] - chain[:, :-1]).norm(dim=-1)
        assert float(step.max()) < 1.2 * SEGMENT_RADII_M[segment], segment
