"""Hard cases for the universal prior's encoders and conditioning maps (models/avatars/prior/encoders.py, maps.py),
swept by hypothesis: maps of zeros, constants, noise and sign patterns at scales from 1e-6 to 1e6, trained-looking
(random) heads: outputs and every gradient finite, the encoders' LeakyReLU chains as linear in scale as they should
be, the log-variance inside its clamp, the KL term non-negative with its hand-derived gradient; unprojecting a frame
seen from inside the head, from a kilometre off, from straight above, through extreme intrinsics: finite colours
within the image's, weights within [0, 1]."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from models.avatars.primitives.chart import chart_sampler
from models.avatars.prior.encoders import ExpressionEncoder, IdentityEncoder, kl_divergence
from models.avatars.prior.maps import average_texture, texture_map
from render.camera import Camera, look_at
from render.rays import Raster

pytestmark = pytest.mark.usefixtures("one_torch_thread")
SWEEP = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
scale = st.sampled_from([0.0, 1e-6, 1e-2, 1.0, 1e3, 1e6])
pattern = st.sampled_from(["zeros", "constant", "noise", "checker", "one texel"])


def conditioning_map(kind: str, size: int, s: float, seed: int) -> torch.Tensor:
    """(1,3,S,S) of a kind, scaled by s."""
    g = torch.Generator().manual_seed(seed)
    x = {"zeros": lambda: torch.zeros(1, 3, size, size),
         "constant": lambda: torch.full((1, 3, size, size), -1.0),
         "noise": lambda: torch.randn(1, 3, size, size, generator=g),
         "checker": lambda: (torch.arange(size)[:, None] + torch.arange(size)[None]).remainder(2).float()
         .mul(2).sub(1).expand(1, 3, size, size).clone(),
         "one texel": lambda: torch.zeros(1, 3, size, size).index_put_((torch.tensor(0), torch.tensor(1),
                                                                        torch.tensor(size // 2),
                                                                        torch.tensor(size // 3)), torch.tensor(1.0)),
         }[kind]()
    return x * s


def trained_like(module: torch.nn.Module, seed: int, biases: bool = True) -> torch.nn.Module:
    """Every weight random (the heads that start at zero included): a prior some way into training."""
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for name, p in module.named_parameters():
            if name.endswith("bias") and not biases:
                p.zero_()
            else:
                p.copy_(torch.randn(p.shape, generator=g) * (0.3 if name.endswith("weight") else 0.1))
    return module


def identity_encoder(size: int) -> IdentityEncoder:
    """Bias maps at every level of the encoder, as the decoder's upsampling asks for them."""
    shapes = [(4, size // 2 ** k, size // 2 ** k) for k in range(int(np.log2(size // 8)) + 1)]
    return IdentityEncoder(size, shapes)


@SWEEP
@given(size=st.sampled_from([8, 16]), tex=pattern, geo=pattern, s_tex=scale, s_geo=scale, seed=st.integers(0, 3))
def test_identity_encoder_finite_with_finite_gradients(size, tex, geo, s_tex, s_geo, seed):
    enc = trained_like(identity_encoder(size), seed)
    t = conditioning_map(tex, size, s_tex, seed).requires_grad_(True)
    g = conditioning_map(geo, size, s_geo, seed + 1).requires_grad_(True)
    out = enc(t, g)
    assert all(torch.isfinite(o).all() for o in out)
    w = torch.Generator().manual_seed(seed)
    loss = sum((o * torch.randn(o.shape, generator=w)).sum() for o in out)  # linear: no overflow of its own
    grads = torch.autograd.grad(loss, [t, g, *enc.parameters()])
    assert all(torch.isfinite(x).all() for x in grads)


@SWEEP
@given(size=st.sampled_from([8, 16]), tex=pattern, geo=pattern, s_tex=scale, s_geo=scale, seed=st.integers(0, 3))
def test_expression_encoder_finite_and_clamped_with_finite_gradients(size, tex, geo, s_tex, s_geo, seed):
    enc = trained_like(ExpressionEncoder(size, latent=4, width=8), seed)
    t = conditioning_map(tex, size, s_tex, seed).requires_grad_(True)
    g = conditioning_map(geo, size, s_geo, seed + 1).requires_grad_(True)
    mean, log_var = enc(t, g)
    assert torch.isfinite(mean).all() and torch.isfinite(log_var).all()
    assert (log_var >= -12.0).all() and (log_var <= 6.0).all()
    kl = kl_divergence(mean, log_var)  # what training takes (its square of a 1e6 mean: 1e12, finite)
    assert torch.isfinite(kl) and float(kl.detach()) >= -1e-6 * mean.numel()  # (float32's rounding of e^lv - 1 - lv)
    grads = torch.autograd.grad(kl + mean.sum(), [t, g, *enc.parameters()])
    assert all(torch.isfinite(x).all() for x in grads)


def test_an_untrained_identity_encoder_writes_zero_bias_maps_for_any_input():
    """Its heads start at zero (an untrained prior decodes as its shared decoder): exactly zero out, even for maps
    of 1e6."""
    enc = identity_encoder(16)
    out = enc(torch.full((1, 3, 16, 16), 1e6), torch.randn(1, 3, 16, 16, generator=torch.Generator().manual_seed(0)))
    assert all(torch.equal(o, torch.zeros_like(o)) for o in out)


@pytest.mark.parametrize("which", ["identity", "expression"])
@pytest.mark.parametrize("s", [1e-6, 1e3, 1e6])
def test_encoders_without_biases_are_linear_in_scale(which, s):
    """Convolutions and LeakyReLU with the biases at zero are positively homogeneous: f(s x) = s f(x), so maps of
    1e-6 or 1e6 pass through without saturating or flushing to zero (float32, 1e-5 relative). The log-variance's
    clamp is the one place that is not: only the means are compared."""
    g = torch.Generator().manual_seed(5)
    t, geo = torch.randn(1, 3, 16, 16, generator=g), torch.randn(1, 3, 16, 16, generator=g)
    if which == "identity":
        enc = trained_like(identity_encoder(16), 2, biases=False)
        f = lambda a, b: torch.cat([o.flatten() for o in enc(a, b)])
    else:
        enc = trained_like(ExpressionEncoder(16, latent=4, width=8), 2, biases=False)
        f = lambda a, b: enc(a, b)[0].flatten()
    with torch.no_grad():
        expect = s * f(t, geo)
        torch.testing.assert_close(f(s * t, s * geo), expect, rtol=1e-5, atol=1e-5 * float(expect.abs().max()))


@SWEEP
@given(mean=st.lists(st.floats(-1e6, 1e6, allow_nan=False), min_size=1, max_size=6),
       log_var=st.lists(st.floats(-12.0, 6.0), min_size=6, max_size=6))
def test_kl_is_non_negative_with_its_hand_derived_gradient(mean, log_var):
    """KL = 1/2 sum(m^2 + e^lv - 1 - lv) >= 0 (e^lv >= 1 + lv), but for the rounding of e^lv - 1 - lv (found by
    the sweep: lv = 8.7e-73, m = 0 gives -4.3e-73; at most a few ulps of e^lv + 1 + |lv|); dKL/dm = m,
    dKL/dlv = (e^lv - 1) / 2 (batch of one), in float64."""
    m = torch.tensor([mean], dtype=torch.float64, requires_grad=True)
    lv = torch.tensor([log_var[: len(mean)]], dtype=torch.float64, requires_grad=True)
    kl = kl_divergence(m, lv)
    rounding = 4e-16 * float((lv.exp() + 1 + lv.abs()).sum().detach())
    assert torch.isfinite(kl) and float(kl.detach()) >= -rounding
    gm, glv = torch.autograd.grad(kl, (m, lv))
    torch.testing.assert_close(gm, m.detach(), rtol=1e-12, atol=0)
    torch.testing.assert_close(glv, 0.5 * (lv.detach().exp() - 1), rtol=1e-12, atol=1e-15)


# ---- unprojecting a frame onto the chart ----------------------------------------------------------------------

@pytest.fixture(scope="module")
def chart(builtin_model):
    m = builtin_model
    centre = 0.5 * (m.template.min(0) + m.template.max(0))
    nose = m.template[np.argmax(m.template[:, 2])].astype(np.float64)  # the vertex furthest forward
    return (chart_sampler(m, 8), torch.as_tensor(np.asarray(m.triangles)), torch.as_tensor(m.template), centre,
            nose)


where = st.sampled_from(["front", "inside", "1 km", "above", "below", "behind", "on the surface"])


@settings(SWEEP, max_examples=20)
@given(place=where, focal=st.sampled_from([1e-3, 1.0, 30.0, 1e6]), off=st.sampled_from([0.0, 50.0, -1e6]),
       size=st.sampled_from([(1, 1), (16, 16), (64, 1)]), colour=st.tuples(*[st.floats(0, 1)] * 3))
def test_texture_map_finite_from_any_camera(chart, place, focal, off, size, colour):
    """A uniform frame unprojected (nothing hides anything: an empty raster) from inside the head, a kilometre
    off, straight above or below, through focal lengths of 1e-3 to 1e6 px and a principal point 1e6 px away: the
    colours finite and each channel within [0, its colour] (bilinear samples of the frame and the zeros past its
    edge), weights within [0, 1]."""
    sampler, tris, verts, c, nose = chart
    eye = nose if place == "on the surface" else c + {
        "front": [0, 0, 0.6], "inside": [0, 0, 0], "1 km": [0, 0, 1e3], "above": [0, 0.6, 0], "below": [0, -0.6, 0],
        "behind": [0, 0, -0.6]}[place]
    target = c if place != "inside" else c + [0, 0, 1]
    w, h = size
    cam = Camera.from_intrinsics(look_at(eye, target), focal, focal, w / 2 + off, h / 2, w, h)
    image = np.broadcast_to(np.asarray(colour, np.float32), (h, w, 3)).copy()
    with np.errstate(all="ignore"):  # x.astype(int) of a texel 1e12 px off: the clip and the mask take it
        rgb, weight = texture_map(sampler, tris, verts, cam, image, Raster.empty(h, w))
    assert np.isfinite(rgb).all() and np.isfinite(weight).all()
    assert (weight >= 0).all() and (weight <= 1 + 1e-6).all()
    assert (rgb >= -1e-6).all() and (rgb <= np.asarray(colour) + 1e-6).all()


def test_texture_map_sees_the_front_from_the_front_and_nothing_from_inside(chart):
    """A numbers check beside the sweep: from 0.6 m in front, a quarter or so of the chart is seen (its front); from
    the head's centre, looking out, none (every surface there faces away)."""
    sampler, tris, verts, c, _ = chart
    image = np.full((16, 16, 3), 0.5, np.float32)
    seen = {}
    for place, eye, target in (("front", c + [0, 0, 0.6], c), ("inside", c, c + [0, 0, 1])):
        cam = Camera(look_at(eye, target), 30.0, 16, 16)
        seen[place] = float((texture_map(sampler, tris, verts, cam, image, Raster.empty(16, 16))[1] > 0).mean())
    assert 0.15 < seen["front"] < 0.45 and seen["inside"] == 0.0, seen


@SWEEP
@given(n=st.integers(1, 4), weights=st.lists(st.sampled_from([0.0, 1e-30, 1e-7, 1e-3, 0.5, 1.0]), min_size=64,
                                              max_size=64), seed=st.integers(0, 3))
def test_average_texture_is_a_convex_mean_or_the_fill(n, weights, seed):
    """Per texel the weighted mean of the frames that saw it (within their colours' range), where none did a fill
    from the seen texels (within their range), or grey when none was seen: finite even where every weight is 0 or
    1e-30."""
    rng = np.random.default_rng(seed)
    colours = [rng.random((4, 4, 3)).astype(np.float32) for _ in range(n)]
    w = [np.asarray(weights[k * 16:(k + 1) * 16], np.float32).reshape(4, 4) for k in range(n)]
    mean, seen = average_texture(colours, w)
    assert np.isfinite(mean).all()
    stack = np.stack(colours)
    lo, hi = stack.min(0), stack.max(0)
    assert ((mean[seen] >= lo[seen] - 1e-6) & (mean[seen] <= hi[seen] + 1e-6)).all()
    if not seen.any():
        np.testing.assert_array_equal(mean, 0.5)
    else:
        assert ((mean[~seen] >= mean[seen].min(0) - 1e-6) & (mean[~seen] <= mean[seen].max(0) + 1e-6)).all()
