"""dispatch.march_rays, the one place that chooses between the torch march and the C code: what it chooses, that it
says so and why, that each choice renders what it chose, and that the torch reference alone never calls the C code."""

from __future__ import annotations

import pytest
import torch

from models.avatars.primitives import dispatch, march, native
from tests.models.avatars.primitives.test_march import camera_rays, random_primitives

built = pytest.mark.skipif(native.library() is None, reason=f"the C march was not built: {native.failure()}")


def scene(dtype=torch.float32, channels: int = 3):
    prims = random_primitives(P=20, M=4, seed=3, dtype=dtype)
    if channels != 3:
        prims.colour = torch.rand(*prims.density.shape, channels, generator=torch.Generator().manual_seed(1),
                                  dtype=dtype)
    origins, dirs = camera_rays(size=16, dtype=dtype)
    return origins, dirs, torch.tensor([0.2, 0.3, 0.4], dtype=dtype), prims


def test_the_torch_march_alone_never_calls_the_c_code(monkeypatch):
    """float32 on the CPU, where the C lookups would serve: march.march without a `gather` looks up by grid_sample
    (the C library, asked for, would raise)."""
    origins, dirs, bg, prims = scene()

    def refuse(*args):
        raise AssertionError("the torch march called the C code")

    monkeypatch.setattr(native, "library", refuse)
    monkeypatch.setattr(native, "trilinear", refuse)
    lists = march.candidate_lists(origins, dirs, prims)
    with torch.inference_mode():
        out = march.march(origins, dirs, bg, prims, lists, 6, 1e-3, min_weight=march.DISPLAY_MIN_WEIGHT,
                          adaptive=True)
    assert out.opacity.max() > 0.5


@built
def test_display_marches_in_c_and_says_so():
    origins, dirs, bg, prims = scene()
    with torch.inference_mode():
        out, ran = dispatch.march_rays(origins, dirs, bg, prims, 6, dispatch.Display(1e-3))
        lists = march.candidate_lists(origins, dirs, prims)
        want = native.march(origins, dirs, bg, prims, lists, 6, 1e-3, march.DISPLAY_MIN_WEIGHT)
    assert ran == dispatch.Ran("c", "c") and str(ran) == "C"
    assert torch.equal(out.rgb, want.rgb) and (out.samples, out.segments) == (want.samples, want.segments)


def test_display_falls_back_to_torch_and_says_why(monkeypatch):
    """Turned off: torch, and the reason; with gradients wanted or more colour channels than the C march holds:
    torch, its lookups still in C where it is built (float32 on the CPU)."""
    origins, dirs, bg, prims = scene()
    monkeypatch.setenv("AVATAR_STUDIO_NATIVE", "0")
    with torch.inference_mode():
        out, ran = dispatch.march_rays(origins, dirs, bg, prims, 6, dispatch.Display(1e-3))
        want = march.march_in_parts(origins, dirs, bg, prims, 6, 1e-3, 1, min_weight=march.DISPLAY_MIN_WEIGHT,
                                    adaptive=True)
    assert ran == dispatch.Ran("torch", "torch", "AVATAR_STUDIO_NATIVE=0")
    assert str(ran) == "torch (AVATAR_STUDIO_NATIVE=0)" and torch.equal(out.rgb, want.rgb)
    monkeypatch.delenv("AVATAR_STUDIO_NATIVE")
    lookups = "c" if native.library() is not None else "torch"
    _, ran = dispatch.march_rays(origins, dirs, bg, prims, 6, dispatch.Display(1e-3))  # gradients on
    assert (ran.march, ran.lookups) == ("torch", lookups)
    assert ran.why == ("gradients wanted" if lookups == "c" else native.failure())
    origins, dirs, bg, wide = scene(channels=native.MAX_CHANNELS + 1)
    with torch.inference_mode():
        _, ran = dispatch.march_rays(origins, dirs, bg, wide, 6, dispatch.Display(1e-3))
    assert ran == dispatch.Ran("torch", lookups, f"{native.MAX_CHANNELS + 1} colour channels (C holds 64)")


def test_training_looks_up_in_c_on_float32_grids_alone():
    """Training always marches in torch; float64 grids (the tests' references) are looked up by grid_sample, and
    give what the torch march gives."""
    origins, dirs, bg, prims = scene(torch.float64)
    out, ran = dispatch.march_rays(origins, dirs, bg, prims, 6)
    want = march.march(origins, dirs, bg, prims, march.candidate_lists(origins, dirs, prims), 6)
    assert ran == dispatch.Ran("torch", "torch", "float64 grids") and torch.equal(out.rgb, want.rgb)
    if native.library() is not None:
        assert dispatch.march_rays(*scene(), 6)[1] == dispatch.Ran("torch", "c")
