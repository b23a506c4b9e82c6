"""The shadow factor: colour = lit colour x share of the light, the lit colour blind to the shadow inputs,
the share starting fully lit, finite under extreme inputs, and the blocked-light loss by hand."""

from __future__ import annotations

import math

import pytest
import torch

from models import losses
from models.fields.codynerf import EFFECTS, SHADOW_BIAS, CoDyNeRFField, FieldConfig, FieldOutput
from models.fields.prior import PriorSamples

L = 5  # landmarks


def inputs(P: int, scale: float = 1.0, dtype=torch.float32, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    r = lambda *shape: torch.randn(*shape, generator=g, dtype=dtype)
    prior = PriorSamples(torch.zeros(P, dtype=torch.long), r(P).abs() * 0.01, r(P, 3) * 0.01,
                         r(P, 3) * 0.01 * scale, r(P, 3) * 0.01 * scale, torch.nn.functional.normalize(r(P, 3), dim=-1))
    geo = FieldOutput(r(P), r(P, 16), r(P, 3), normal=torch.nn.functional.normalize(r(P, 3), dim=-1))
    view = torch.nn.functional.normalize(r(P, 3), dim=-1)
    return geo, prior, view, r(1, 8), r(1, 3 * L) * 0.05 * scale


def randomised(field: CoDyNeRFField) -> CoDyNeRFField:
    """The factor's zero-initialised last layer given random weights, as training would."""
    torch.manual_seed(1)
    last = field.shadow_net.net[-1]
    torch.nn.init.normal_(last.weight, std=0.5)
    torch.nn.init.normal_(last.bias, std=0.5)
    return field


def test_colour_is_lit_times_light_and_starts_lit():
    torch.manual_seed(0)
    field = CoDyNeRFField(FieldConfig(effects=EFFECTS), L)
    geo, prior, view, phi, lm = inputs(64)
    lit, light = field.appearance_terms(geo, prior, view, phi, lm)
    assert lit.shape == (64, 3) and light.shape == (64, 1)
    # zero last layer: every point gets sigmoid(SHADOW_BIAS) = 0.982 of the light
    torch.testing.assert_close(light, torch.full_like(light, 1 / (1 + math.exp(-SHADOW_BIAS))))
    randomised(field)
    lit, light = field.appearance_terms(geo, prior, view, phi, lm)
    assert torch.equal(field.appearance(geo, prior, view, phi, lm), lit * light)
    assert (light > 0).all() and (light < 1).all() and light.std() > 0.01


def test_lit_colour_ignores_the_shadow_inputs():
    torch.manual_seed(0)
    field = randomised(CoDyNeRFField(FieldConfig(effects=EFFECTS), L))
    geo, prior, view, phi, lm = inputs(32)
    _, prior2, _, _, lm2 = inputs(32, seed=5)
    moved = PriorSamples(prior.nearest, prior.distance, prior.offset, prior2.expression_offset, prior2.pose_offset,
                         prior.mesh_normal)
    lit_a, light_a = field.appearance_terms(geo, prior, view, phi, lm)
    lit_b, light_b = field.appearance_terms(geo, moved, view, phi, lm2)
    assert torch.equal(lit_a, lit_b)
    assert (light_a - light_b).abs().max() > 1e-3


def test_legacy_layout_has_no_factor():
    """Avatars trained before the factor: one appearance network reading the shadow inputs (Eq. 7 as written)."""
    new = CoDyNeRFField(FieldConfig(effects=EFFECTS), L)
    old = CoDyNeRFField(FieldConfig(effects=EFFECTS, shadow_factor=False), L)
    assert old.shadow_net is None and new.shadow_net is not None
    c = FieldConfig()
    assert old.appearance_net.net[0].in_features == new.appearance_net.net[0].in_features + c.landmark_features + 6
    geo, prior, view, phi, lm = inputs(8)
    lit, light = old.appearance_terms(geo, prior, view, phi, lm)
    assert light is None and torch.equal(old.appearance(geo, prior, view, phi, lm), lit)
    # without shadows in the effect set there is neither
    assert CoDyNeRFField(FieldConfig(effects=("shading",)), L).shadow_net is None


@pytest.mark.parametrize("scale", [1.0, 1e4, 1e8])
def test_extreme_shadow_inputs_stay_finite(scale):
    """Points far from the mesh (huge prior offsets) and wild landmarks: the colour, the share of the light
    and their gradients stay finite, and the share stays in [0, 1]."""
    torch.manual_seed(0)
    field = randomised(CoDyNeRFField(FieldConfig(effects=EFFECTS), L))
    geo, prior, view, phi, lm = inputs(16, scale)
    prior.expression_offset.requires_grad_(True)
    lm.requires_grad_(True)
    lit, light = field.appearance_terms(geo, prior, view, phi, lm)
    assert torch.isfinite(lit).all() and torch.isfinite(light).all() and (light >= 0).all() and (light <= 1).all()
    (lit * light).sum().backward()
    assert torch.isfinite(prior.expression_offset.grad).all() and torch.isfinite(lm.grad).all()
    assert all(torch.isfinite(p.grad).all() for p in field.parameters() if p.grad is not None)


def test_factor_gradients_match_finite_differences():
    torch.manual_seed(0)
    field = randomised(CoDyNeRFField(FieldConfig(effects=EFFECTS), L)).double()
    geo, prior, view, phi, lm = inputs(4, dtype=torch.float64)

    def colour(expr: torch.Tensor, landmarks: torch.Tensor) -> torch.Tensor:
        p = PriorSamples(prior.nearest, prior.distance, prior.offset, expr, prior.pose_offset, prior.mesh_normal)
        return field.appearance(geo, p, view, phi, landmarks)

    assert torch.autograd.gradcheck(colour, (prior.expression_offset.clone().requires_grad_(True),
                                             lm.clone().requires_grad_(True)))


def test_blocked_light_by_hand():
    weights = torch.tensor([[0.5, 0.5, 0.0], [0.2, 0.0, 0.0]], requires_grad=True)
    light = torch.tensor([[1.0, 0.2, 0.0], [0.5, 1.0, 1.0]], requires_grad=True)
    value = losses.blocked_light(weights, light)
    # ray 1: 0.5 * 0 + 0.5 * 0.8 + 0 = 0.4; ray 2: 0.2 * 0.5 = 0.1; mean 0.25
    assert value.item() == pytest.approx(0.25)
    value.backward()
    assert weights.grad is None  # the weights say where to look, nothing to shrink
    torch.testing.assert_close(light.grad, -weights.detach() / 2)


def test_factor_reads_the_mesh_shadow_map_where_the_capture_has_a_light():
    torch.manual_seed(0)
    cfg = FieldConfig(effects=EFFECTS, light_dir=(0.0, 1.0, 0.0))
    assert cfg.mesh_light and not FieldConfig(effects=("shading", "specular"), light_dir=(0.0, 1.0, 0.0)).mesh_light
    field = randomised(CoDyNeRFField(cfg, L))
    geo, prior, view, phi, lm = inputs(16)
    with pytest.raises(ValueError, match="mesh_light"):
        field.appearance_terms(geo, prior, view, phi, lm)
    lit_a, light_a = field.appearance_terms(geo, prior, view, phi, lm, torch.ones(16))
    lit_b, light_b = field.appearance_terms(geo, prior, view, phi, lm, torch.zeros(16))
    assert torch.equal(lit_a, lit_b) and (light_a - light_b).abs().max() > 1e-3
