"""The shadow factor: colour = L (1 - k (1 - S)) with S the key light's visibility from tau and the guide
mesh's shadow map; L blind to the mesh's visibility, S blind to the landmarks and offsets, starting fully lit,
finite under extreme inputs; the layout without a recorded light is Eq. 7 as written; the blocked-light loss
by hand."""

from __future__ import annotations

import math

import pytest
import torch

from models.avatars.codynerf.field import SHADOW_BIAS, CoDyNeRFField, FieldConfig, FieldOutput
from models.avatars.codynerf.prior import PriorSamples
from models.avatars.components import losses
from models.avatars.components.encoding import encoded_size, frequency_encoding
from models.avatars.effects import EFFECTS

L = 5  # landmarks
LIT = FieldConfig(effects=EFFECTS, light_dir=(0.0, 1.0, 0.0))


def inputs(P: int, scale: float = 1.0, dtype=torch.float32, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    r = lambda *shape: torch.randn(*shape, generator=g, dtype=dtype)
    prior = PriorSamples(torch.zeros(P, dtype=torch.long), r(P).abs() * 0.01, r(P, 3) * 0.01,
                         r(P, 3) * 0.01 * scale, r(P, 3) * 0.01 * scale, torch.nn.functional.normalize(r(P, 3), dim=-1))
    geo = FieldOutput(r(P), r(P, 16) * scale, r(P, 3), normal=torch.nn.functional.normalize(r(P, 3), dim=-1))
    view = torch.nn.functional.normalize(r(P, 3), dim=-1)
    vis = torch.rand(P, generator=g, dtype=dtype)
    return geo, prior, view, r(1, 8), r(1, 3 * L) * 0.05 * scale, vis


def randomised(field: CoDyNeRFField) -> CoDyNeRFField:
    """The factor's zero-initialised last layer given random weights, as training would."""
    torch.manual_seed(1)
    last = field.shadow_net.net[-1]
    torch.nn.init.normal_(last.weight, std=1.0)
    torch.nn.init.constant_(last.bias, -SHADOW_BIAS)  # visibilities about 0.5
    return field


def test_colour_is_lit_times_factor_and_starts_lit():
    torch.manual_seed(0)
    field = CoDyNeRFField(LIT, L)
    geo, prior, view, phi, lm, vis = inputs(64)
    lit, factor, visibility = field.appearance_terms(geo, prior, view, phi, lm, vis)
    assert lit.shape == (64, 3) and factor.shape == visibility.shape == (64, 1)
    # zero last layer: the visibility is sigmoid(SHADOW_BIAS) = 0.982 everywhere, and the factor is
    # 1 - k (1 - 0.982) for the key light's share k that the appearance network gives beside L
    s0 = 1 / (1 + math.exp(-SHADOW_BIAS))
    torch.testing.assert_close(visibility, torch.full_like(visibility, s0))
    reflect = 2 * (view * geo.normal).sum(-1, keepdim=True) * geo.normal - view
    lm_f = field.landmarks(lm).expand(64, -1)
    raw = field.appearance_net(torch.cat([geo.rgb, frequency_encoding(view, 2), geo.normal,
                                          frequency_encoding(reflect, 2), lm_f, prior.expression_offset / 0.25,
                                          prior.pose_offset / 0.25], -1), phi, code_at=16 + encoded_size(3, 2))
    k = torch.sigmoid(raw)[:, 3:]
    torch.testing.assert_close(factor, 1 - k * (1 - s0))
    torch.testing.assert_close(lit, torch.sigmoid(raw)[:, :3])
    assert (factor > 0.98).all() and (factor < 1).all()
    randomised(field)
    lit, factor, visibility = field.appearance_terms(geo, prior, view, phi, lm, vis)
    assert torch.equal(field.appearance(geo, prior, view, phi, lm, vis), lit * factor)
    assert (factor > 0).all() and (factor < 1).all() and visibility.std() > 0.01


def test_lit_colour_ignores_the_mesh_and_visibility_ignores_the_landmarks():
    torch.manual_seed(0)
    field = randomised(CoDyNeRFField(LIT, L))
    geo, prior, view, phi, lm, vis = inputs(32)
    _, prior2, _, _, lm2, vis2 = inputs(32, seed=5)
    moved = PriorSamples(prior.nearest, prior.distance, prior.offset, prior2.expression_offset, prior2.pose_offset,
                         prior.mesh_normal)
    lit_a, _, vis_a = field.appearance_terms(geo, prior, view, phi, lm, vis)
    lit_b, _, vis_b = field.appearance_terms(geo, prior, view, phi, lm, vis2)  # the mesh's shadow moved
    lit_c, _, vis_c = field.appearance_terms(geo, moved, view, phi, lm2, vis)  # expression and pose changed
    assert torch.equal(lit_a, lit_b) and (vis_a - vis_b).abs().max() > 1e-3
    assert torch.equal(vis_a, vis_c) and (lit_a - lit_c).abs().max() > 1e-4
    with pytest.raises(ValueError, match="mesh_light"):
        field.appearance_terms(geo, prior, view, phi, lm)


def test_without_a_recorded_light_eq7_as_written():
    """No light in the capture (a tracked video, avatars trained before the factor): one appearance network
    reads the shadow inputs, three outputs, no factor."""
    old = CoDyNeRFField(FieldConfig(effects=EFFECTS), L)
    new = CoDyNeRFField(LIT, L)
    assert old.shadow_net is None and new.shadow_net is not None
    assert old.appearance_net.net[0].in_features == new.appearance_net.net[0].in_features
    assert (old.appearance_net.net[-1].out_features, new.appearance_net.net[-1].out_features) == (3, 4)
    geo, prior, view, phi, lm, _ = inputs(8)
    lit, factor, vis = old.appearance_terms(geo, prior, view, phi, lm)
    assert factor is None and vis is None and torch.equal(old.appearance(geo, prior, view, phi, lm), lit)
    # a light but no shadows in the effect set: no factor either
    assert not FieldConfig(effects=("shading",), light_dir=(0.0, 1.0, 0.0)).shadow_factor


@pytest.mark.parametrize("scale", [1.0, 1e4, 1e8])
def test_extreme_inputs_stay_finite(scale):
    """Points far from the mesh (huge prior offsets, huge features) and wild landmarks: the colour, the factor
    and their gradients stay finite, and the factor stays in [0, 1]."""
    torch.manual_seed(0)
    field = randomised(CoDyNeRFField(LIT, L))
    geo, prior, view, phi, lm, vis = inputs(16, scale)
    prior.expression_offset.requires_grad_(True)
    geo.rgb.requires_grad_(True)
    lit, factor, _ = field.appearance_terms(geo, prior, view, phi, lm, vis)
    assert torch.isfinite(lit).all() and torch.isfinite(factor).all() and (factor >= 0).all() and (factor <= 1).all()
    (lit * factor).sum().backward()
    assert torch.isfinite(prior.expression_offset.grad).all() and torch.isfinite(geo.rgb.grad).all()
    assert all(torch.isfinite(p.grad).all() for p in field.parameters() if p.grad is not None)


def test_factor_gradients_match_finite_differences():
    torch.manual_seed(0)
    field = randomised(CoDyNeRFField(LIT, L)).double()
    geo, prior, view, phi, lm, vis = inputs(4, dtype=torch.float64)

    def colour(tau: torch.Tensor, visibility: torch.Tensor) -> torch.Tensor:
        g = FieldOutput(geo.sigma, tau, geo.x_canonical, normal=geo.normal)
        return field.appearance(g, prior, view, phi, lm, visibility)

    assert torch.autograd.gradcheck(colour, (geo.rgb.clone().requires_grad_(True), vis.clone().requires_grad_(True)))


def test_blocked_light_by_hand():
    weights = torch.tensor([[0.5, 0.5, 0.0], [0.2, 0.0, 0.0]], requires_grad=True)
    light = torch.tensor([[1.0, 0.2, 0.0], [0.5, 1.0, 1.0]], requires_grad=True)
    value = losses.blocked_light(weights, light)
    # ray 1: 0.5 * 0 + 0.5 * 0.8 + 0 = 0.4; ray 2: 0.2 * 0.5 = 0.1; mean 0.25
    assert value.item() == pytest.approx(0.25)
    value.backward()
    assert weights.grad is None  # the weights say where to look, nothing to shrink
    torch.testing.assert_close(light.grad, -weights.detach() / 2)
