"""The mesh-guided sampler: shells about the surface, the box elsewhere, nothing outside."""

from __future__ import annotations

import torch

from render.sampling import shell_or_box_samples, stratified

D = torch.float64


def test_stratified_even_and_jittered():
    t0, t1 = stratified(torch.tensor([1.0], dtype=D), torch.tensor([2.0], dtype=D), 4, None)
    torch.testing.assert_close(t0[0], torch.tensor([1.0, 1.25, 1.5, 1.75], dtype=D))
    torch.testing.assert_close(t1[0], torch.tensor([1.25, 1.5, 1.75, 2.0], dtype=D))
    g = torch.Generator().manual_seed(0)
    a0, a1 = stratified(torch.zeros(100, dtype=D), torch.ones(100, dtype=D), 8, g)
    assert (a1 > a0).all() and torch.equal(a0[:, 1:], a1[:, :-1])  # contiguous, non-empty
    assert (a0[:, 0] == 0).all() and (a1[:, -1] == 1).all()
    stratum = torch.arange(8, dtype=D) / 8
    assert ((a0[:, 1:] - stratum[1:]).abs() <= 0.5 / 8).all()  # each edge stays in its stratum


def test_shell_box_and_miss():
    o = torch.tensor([[0.0, 0, 2]] * 3, dtype=D)
    d = torch.tensor([[0.0, 0, -1], [0.0, 0, -1], [0.0, 1, 0]], dtype=D)
    surface = torch.tensor([1.9, float("inf"), float("inf")], dtype=D)
    s = shell_or_box_samples(o, d, surface, -torch.ones(3, dtype=D), torch.ones(3, dtype=D), 4, shell_m=0.02)
    # Ray 0 sees the surface at t = 1.9: samples in [1.88, 1.92]; ray 1 misses the mesh: the box, t in [1, 3];
    # ray 2 runs parallel to the box's top face from outside it: no samples.
    assert s.valid.tolist() == [True, True, False]
    torch.testing.assert_close(s.t_starts[0, 0], torch.tensor(1.88, dtype=D))
    torch.testing.assert_close(s.t_ends[0, -1], torch.tensor(1.92, dtype=D))
    torch.testing.assert_close(s.t_starts[1, 0], torch.tensor(1.0, dtype=D))
    torch.testing.assert_close(s.t_ends[1, -1], torch.tensor(3.0, dtype=D))
    assert (s.deltas[2] == 0).all()


def test_camera_inside_the_box_starts_at_zero():
    s = shell_or_box_samples(torch.zeros(1, 3, dtype=D), torch.tensor([[1.0, 0, 0]], dtype=D),
                             torch.tensor([0.01], dtype=D), -torch.ones(3, dtype=D), torch.ones(3, dtype=D), 4)
    assert s.valid.item() and s.t_starts[0, 0] == 0 and torch.isclose(s.t_ends[0, -1], torch.tensor(0.03, dtype=D))
