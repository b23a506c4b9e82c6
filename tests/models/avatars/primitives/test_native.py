"""The display march in C (models/avatars/primitives/native.py) against the torch march it stands in for: the same
images, opacity and depth (exactly the same work where nothing stops early), the same on any number of threads, a
newer request stopping it, a clear error where it cannot be built, and the demo avatar's frame the same either
way."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from models.avatars.base import RenderCancelled
from models.avatars.primitives import dispatch, march, native
from models.avatars.rendering import RenderOptions, render_image
from tests.models.avatars.primitives.test_march import camera_rays, random_primitives

pytestmark = pytest.mark.skipif(native.library() is None, reason=f"the C march was not built: {native.failure()}")


def scene(seed: int, size: int = 32):
    prims = random_primitives(P=40, M=8, seed=seed, dtype=torch.float32)
    origins, dirs = camera_rays(size=size, yaw=25.0 * seed, dtype=torch.float32)
    bg = torch.rand(len(origins), 3, generator=torch.Generator().manual_seed(seed))
    return prims, origins, dirs, bg, march.candidate_lists(origins, dirs, prims, rays_per_tile=16)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_without_early_stops_the_c_march_does_the_torch_marchs_work(seed):
    """No early termination and every colour looked up: the same segments, the same samples, the same sums (to
    float32's rounding)."""
    prims, origins, dirs, bg, lists = scene(seed)
    with torch.inference_mode():
        ref = march.march(origins, dirs, bg, prims, lists, 8, 0.0, min_weight=0.0, adaptive=True)
        out = native.march(origins, dirs, bg, prims, lists, 8, 0.0, 0.0)
    assert ref.opacity.max() > 0.9 and (ref.opacity < 1e-6).any()  # opaque primitives and empty space
    assert (out.segments, out.samples) == (ref.segments, ref.samples)
    for a, b in ((out.rgb, ref.rgb), (out.opacity, ref.opacity)):
        torch.testing.assert_close(a, b, atol=1e-4, rtol=0)  # a fortieth of an 8-bit step
    torch.testing.assert_close(out.depth, ref.depth, atol=1e-4, rtol=0)  # metres: a tenth of a millimetre


@pytest.mark.parametrize("seed", [3, 4])
def test_with_early_stops_the_c_march_shows_what_display_shows(seed):
    """Display's settings (stop once 1e-3 of the light is left, colour where a weight reaches 1e-4): the C march
    stops at the candidate where a ray turns opaque, the torch one at the end of a wave of four, so they differ by
    at most what the stop leaves, and the C march does less."""
    prims, origins, dirs, bg, lists = scene(seed)
    with torch.inference_mode():
        ref = march.march(origins, dirs, bg, prims, lists, 8, 1e-3, min_weight=march.DISPLAY_MIN_WEIGHT,
                          adaptive=True)
        out = native.march(origins, dirs, bg, prims, lists, 8, 1e-3, march.DISPLAY_MIN_WEIGHT)
    torch.testing.assert_close(out.rgb, ref.rgb, atol=2e-3, rtol=0)
    torch.testing.assert_close(out.opacity, ref.opacity, atol=2e-3, rtol=0)
    assert out.segments <= ref.segments and out.samples <= ref.samples
    assert (out.opacity <= 1 + 1e-6).all() and (out.opacity >= 0).all()


def test_threads_split_the_rays_and_change_nothing():
    prims, origins, dirs, bg, lists = scene(5, size=48)
    with torch.inference_mode():
        one = native.march(origins, dirs, bg, prims, lists, 8, 1e-3, 1e-4, parts=1)
        for parts in (2, 3):
            split = native.march(origins, dirs, bg, prims, lists, 8, 1e-3, 1e-4, parts=parts)
            assert torch.equal(split.rgb, one.rgb) and torch.equal(split.depth, one.depth)
            assert (split.samples, split.segments) == (one.samples, one.segments)


def test_a_newer_request_stops_it():
    prims, origins, dirs, bg, lists = scene(6, size=64)
    asked = []

    def should_stop():
        asked.append(1)
        return len(asked) > 1  # the second chunk of 2048 rays

    with torch.inference_mode(), pytest.raises(RenderCancelled):
        native.march(origins, dirs, bg, prims, lists, 8, 1e-3, 1e-4, should_stop=should_stop)
    assert len(asked) == 2


def test_a_source_that_does_not_build_names_itself(tmp_path):
    bad = tmp_path / "broken.c"
    bad.write_text("void march_rays( {\n")
    with pytest.raises(RuntimeError, match=r"broken\.c"):
        native.build(bad, tmp_path / "cache")
    assert not list((tmp_path / "cache").glob("*.so"))  # nothing half-built left behind
    good = tmp_path / "fine.c"
    good.write_text("int twice(int x) { return 2 * x; }\n")
    lib = native.build(good, tmp_path / "cache")
    assert lib.is_file() and native.build(good, tmp_path / "cache") == lib  # built once


def test_the_build_is_the_processors_own_where_the_compiler_can_and_portable_where_not(tmp_path, monkeypatch):
    """NATIVE_FLAGS first, the library named by the processor too (another processor, another file); flags the
    compiler refuses: the portable build, which works."""
    import ctypes

    source = tmp_path / "fine.c"
    source.write_text("int twice(int x) { return 2 * x; }\n")
    own = native.build(source, tmp_path / "cache")
    monkeypatch.setattr(native, "processor_key", lambda: "another processor")
    other = native.build(source, tmp_path / "cache")
    assert own.is_file() and other.is_file() and own != other
    monkeypatch.setattr(native, "NATIVE_FLAGS", ("-fno-such-flag-anywhere",))
    portable = native.build(source, tmp_path / "cache" / "portable")
    assert portable.is_file() and ctypes.CDLL(str(portable)).twice(21) == 42
    assert len(list((tmp_path / "cache" / "portable").iterdir())) == 1  # the refused build left nothing behind


def test_the_demo_avatar_renders_the_same_frame_either_way(monkeypatch, demo_avatar_and_raster):
    avatar, raster, controls, cam = demo_avatar_and_raster
    with torch.inference_mode():
        fast = render_image(avatar, cam, controls, RenderOptions(buffers=None), raster)
        monkeypatch.setenv("AVATAR_STUDIO_NATIVE", "0")
        slow = render_image(avatar, cam, controls, RenderOptions(buffers=None), raster)
    assert fast["opacity"].max() > 0.99 and fast["opacity"].min() < 0.01  # the head and the space round it
    for name in ("rgb", "normals"):
        mse = float(np.mean((fast[name] - slow[name]) ** 2))
        assert 10 * np.log10(1.0 / max(mse, 1e-20)) > 50.0, name
    assert np.abs(fast["opacity"] - slow["opacity"]).max() < 2e-3


@pytest.fixture
def demo_avatar_and_raster():
    from models.avatars.registry import load_avatar
    from models.head.controls import Controls
    from render.camera import framing_camera
    from render.gl.context import GLContext
    from render.gl.raster import Rasterizer
    from tests.conftest import DEMO

    avatar, _ = load_avatar(DEMO)
    gl = GLContext.headless()
    raster = Rasterizer(gl)
    cam = framing_camera(avatar.card.rest_vertices(), 20.0, 5.0, fov_y_deg=18.0, width_px=96, height_px=96)
    yield avatar, raster, avatar.card.at_rest(Controls()), cam
    raster.release()
    gl.release()


def test_trilinear_lookups_and_their_gradients_match_the_gathered_reference():
    """Training's lookups in C (native.trilinear) against march.trilinear (explicit gathers, autograd): values and
    the gradients for the grids and the coordinates, inside the grid and clamped at its faces."""
    g = torch.Generator().manual_seed(0)
    P, M, C, N = 5, 4, 3, 300
    values = torch.rand(P, M, M, M, C, generator=g, dtype=torch.float64, requires_grad=True)
    prim = torch.randint(P, (N,), generator=g)
    local = (torch.rand(N, 3, generator=g, dtype=torch.float64) * 2.4 - 1.2).requires_grad_(True)
    outs, grads = [], []
    for fn in (native.trilinear, march.trilinear):
        out = fn(values, prim, local.clamp(-1.0, 1.0))  # as Lookups.points clamps them
        outs.append(out)
        grads.append(torch.autograd.grad((out * torch.linspace(-1, 2, C, dtype=out.dtype)).square().sum(),
                                         (values, local)))
    assert (local.detach().abs() > 1).any(1).sum() > 50  # many clamped at a face
    torch.testing.assert_close(outs[0], outs[1], atol=1e-6, rtol=0)
    for a, b in zip(grads[0], grads[1], strict=True):
        assert b.abs().max() > 0.1
        torch.testing.assert_close(a, b, atol=1e-5, rtol=1e-5)


def test_training_marches_with_c_lookups_as_with_grid_sample(monkeypatch):
    """The training march (one pass, gradients) on float32 grids looks up in C; with it off, by grid_sample: the
    same image and the same gradients for the grids and the boxes."""
    prims = random_primitives(P=30, M=6, seed=9, dtype=torch.float32)
    origins, dirs = camera_rays(size=24, yaw=10.0, dtype=torch.float32)
    bg = torch.tensor([0.2, 0.3, 0.4])
    results = []
    for setting in ("1", "0"):
        monkeypatch.setenv("AVATAR_STUDIO_NATIVE", setting)
        leaves = [t.detach().clone().requires_grad_(True) for t in (prims.half_sizes, prims.density, prims.colour)]
        p = march.Primitives(prims.centres, prims.rotations, *leaves)
        out, ran = dispatch.march_rays(origins, dirs, bg, p, 6)
        assert ran == (dispatch.Ran("torch", "c") if setting == "1" else
                       dispatch.Ran("torch", "torch", "AVATAR_STUDIO_NATIVE=0"))
        (out.rgb.square().sum() + out.depth.sum()).backward()
        results.append((out.rgb.detach(), *(t.grad for t in leaves)))
    assert results[0][0].std() > 0.05
    for a, b in zip(*results, strict=True):
        torch.testing.assert_close(a, b, atol=2e-5 * max(1.0, float(b.abs().max())), rtol=1e-4)


def test_the_set_up_builds_the_library_or_says_why_not(tmp_path, monkeypatch, capsys):
    """`make native` runs main(): with a compiler it builds the library into the cache and names it; without one it
    says the torch march runs instead, and exits 0 (set-up goes on)."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "with"))
    assert native.main() == 0
    built = list((tmp_path / "with" / "avatar-studio" / "native").glob("native_march-*.so"))
    assert len(built) == 1 and str(built[0]) in capsys.readouterr().out
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "without"))
    monkeypatch.setenv("CC", str(tmp_path / "no-such-compiler"))
    assert native.main() == 0
    assert "the torch march runs instead" in capsys.readouterr().err
    assert not (tmp_path / "without" / "avatar-studio" / "native").exists() or \
        not list((tmp_path / "without" / "avatar-studio" / "native").glob("*.so"))
