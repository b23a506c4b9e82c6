"""Hard cases for the volumetric primitives, swept by hypothesis: primitives collapsed to zero size or
flat, densities of 0 and 1e6, rays from kilometres away, along the boxes' faces and from inside a box, decoder
offsets far beyond their range: every output finite, opacity within [0, 1], and the gradients training takes
finite too; the display march in C (native.py) finite on the same cases."""

from __future__ import annotations

import numpy as np
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from models.avatars.primitives import march, native
from models.head.lbs import rotation_matrix_from_axis_angle

SWEEP = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
P, M = 6, 3
size = st.sampled_from([0.0, 1e-9, 1e-4, 0.02, 0.5])
density = st.sampled_from([0.0, 1e-3, 50.0, 1e4, 1e6])
coord = st.floats(-1e3, 1e3, allow_nan=False, width=32)
near = st.floats(-0.0625, 0.0625, allow_nan=False, width=32)


def unit(v) -> np.ndarray:
    v = np.asarray(v, np.float32)
    n = np.linalg.norm(v)
    return v / n if n > 1e-3 else np.array([0.0, 0.0, 1.0], np.float32)


@SWEEP
@given(st.lists(st.tuples(size, size, size), min_size=P, max_size=P), st.lists(density, min_size=P, max_size=P),
       st.lists(st.tuples(near, near, near), min_size=P, max_size=P),
       st.one_of(st.tuples(coord, coord, coord), st.tuples(near, near, near)),
       st.lists(st.one_of(st.tuples(coord, coord, coord), st.sampled_from([(1, 0, 0), (0, 1, 0), (0, 0, -1)])),
                min_size=1, max_size=5),
       st.booleans())
def test_march_stays_finite(halves, densities, centres, eye, directions, shared):
    g = torch.Generator().manual_seed(0)
    half = torch.tensor(halves, dtype=torch.float32).requires_grad_(True)
    dens = (torch.tensor(densities)[:, None, None, None] * torch.rand(P, M, M, M, generator=g)).requires_grad_(True)
    rot = rotation_matrix_from_axis_angle(torch.randn(P, 3, generator=g))
    rot[0] = torch.eye(3)  # axis-aligned: the axis directions run along its faces
    prims = march.Primitives(torch.tensor(centres), rot, half, dens, torch.rand(P, M, M, M, 3, generator=g))
    dirs = torch.as_tensor(np.stack([unit(d) for d in directions]))
    origins = torch.as_tensor(np.asarray(eye, np.float32)).expand(len(dirs), 3).contiguous()
    if not shared:  # rays of many origins: a face-grazing ray along primitive 0's top face
        origins = origins.clone()
        origins[0] = prims.centres[0].detach() + torch.tensor([-1.0, float(halves[0][1]), 0.0])
        dirs = dirs.clone()
        dirs[0] = torch.tensor([1.0, 0.0, 0.0])
    lists = march.candidate_lists(origins, dirs, prims)
    out = march.march(origins, dirs, torch.tensor([0.5, 0.5, 0.5]), prims, lists, samples=4)
    for t in (out.rgb, out.opacity, out.depth):
        assert torch.isfinite(t).all()
    assert (out.opacity >= -1e-6).all() and (out.opacity <= 1 + 1e-5).all()
    if native.library() is not None:  # the display march in C: the same hard cases, finite and within [0, 1]
        with torch.no_grad():
            shown = native.march(origins, dirs, torch.tensor([0.5, 0.5, 0.5]), prims, lists, 4, 1e-3, 1e-4)
        for t in (shown.rgb, shown.opacity, shown.depth):
            assert torch.isfinite(t).all()
        assert (shown.opacity >= 0).all() and (shown.opacity <= 1 + 1e-5).all()
    if out.segments:  # some ray met a primitive (else nothing depends on them)
        (out.rgb.sum() + out.opacity.sum() + out.depth.sum()).backward()
        assert torch.isfinite(half.grad).all() and torch.isfinite(dens.grad).all()
