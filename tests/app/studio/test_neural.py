"""The renderer process's passes, run in this process on the shipped demo: every pass while nothing is timed, then
only the passes worth rendering once a finer pass has shown it fits the first-pixels budget (by the median of its
last few times)."""

from __future__ import annotations

import queue

import pytest

from app.studio.neural import PASS_BUDGET_MS, TIMES_KEPT, Request, measure_presets, render_passes
from models.avatars.registry import load_avatar
from models.avatars.rendering import RenderOptions, render_image
from models.head.controls import Controls
from render.camera import framing_camera
from render.gl.raster import Rasterizer
from tests.conftest import DEMO


@pytest.mark.gl
def test_a_fast_final_pass_leaves_the_coarse_passes_out(gl):
    avatar, _ = load_avatar(DEMO)
    raster = Rasterizer(gl)
    cam = framing_camera(avatar.card.rest_vertices(), 20, 5, fov_y_deg=18.0, width_px=48, height_px=48)
    request = Request(avatar.card.at_rest(Controls()), cam, ("draft", "preview", "final"))
    results, timed = queue.Queue(), {}
    sent = lambda: [results.get_nowait() for _ in range(results.qsize())]
    shown = lambda: [m[2] for m in sent() if m[0] == "result"]
    render_passes(avatar, raster, request, 1, lambda rid: False, results, timed)
    messages = sent()  # each pass says when it starts and how long it should take (nothing timed yet: not known)
    assert [m[0] for m in messages] == ["started", "result"] * 3 and all(m[2] is None for m in messages[::2])
    assert [m[2] for m in messages[1::2]] == ["draft", "preview", "final"]  # nothing timed yet: coarse to fine
    assert set(timed) == {("draft", 48), ("preview", 48), ("final", 48)}
    assert timed["final", 48][-1] <= PASS_BUDGET_MS  # a 48 px frame of the demo
    first = timed["final", 48][-1]
    render_passes(avatar, raster, request, 2, lambda rid: False, results, timed)
    messages = sent()
    assert [m[:3] for m in messages] == [("started", 2, first), ("result", 2, "final")]  # due by its last time
    assert len(timed["final", 48]) == 2  # each pass's times kept
    timed["final", 48] = [PASS_BUDGET_MS + 50, 10.0, 20.0]  # one slow final does not decide
    render_passes(avatar, raster, request, 3, lambda rid: False, results, timed)
    assert shown() == ["final"]
    assert len(timed["final", 48]) == TIMES_KEPT and timed["final", 48][0] == 10.0  # the oldest one dropped
    timed["final", 48] = [PASS_BUDGET_MS + 1] * 3  # a final too slow: the preview first, if it fits
    render_passes(avatar, raster, request, 4, lambda rid: False, results, timed)
    assert shown() == ["preview", "final"]
    raster.release()


@pytest.mark.gl
def test_the_quality_panels_figures_compare_every_preset_at_the_final_size(gl):
    """The demo's presets render at 1/4, 3/8 and all of its 256 px capture size: 64 and 96 px images are compared
    with the final's 256 px (nearest upsampling by any ratio, not only whole ones)."""
    avatar, _ = load_avatar(DEMO)
    raster = Rasterizer(gl)
    figures = measure_presets(avatar, raster, lambda: False)
    raster.release()
    assert figures.size_px == avatar.card.capture_px == 256
    assert set(figures.ms) == {"draft", "preview", "final"} and all(ms > 0 for ms in figures.ms.values())
    assert figures.psnr_vs_final["final"] == float("inf")
    assert figures.march == avatar.describe_display() != ""  # the primitives' march, C or torch
    assert 15.0 < figures.psnr_vs_final["draft"] < figures.psnr_vs_final["preview"] < 60.0


@pytest.mark.gl
def test_the_quality_panel_says_which_march_displays(gl, monkeypatch):
    """The avatar says what rendered its last display batch: the primitives' march, C or torch and why (nothing
    before it renders); a model with one way, nothing."""
    from models.avatars.primitives import native
    from tests.conftest import CODYNERF_DEMO

    avatar, _ = load_avatar(DEMO)
    raster = Rasterizer(gl)
    cam = framing_camera(avatar.card.rest_vertices(), 20, 5, fov_y_deg=18.0, width_px=16, height_px=16)

    def shown() -> str:
        render_image(avatar, cam, avatar.card.at_rest(Controls()), RenderOptions(buffers=()), raster)
        return avatar.describe_display()

    assert avatar.describe_display() == ""
    assert shown() == ("C" if native.library() is not None else f"torch ({native.failure()})")
    if native.failure() is None:  # built: turned off, the torch march and why
        monkeypatch.setenv("AVATAR_STUDIO_NATIVE", "0")
        assert shown() == "torch (AVATAR_STUDIO_NATIVE=0)"
    raster.release()
    assert load_avatar(CODYNERF_DEMO)[0].describe_display() == ""


@pytest.mark.gl
def test_a_capture_frames_own_room_stands_behind_its_render(gl, tmp_path):
    """A request that names its frame's room (a capture whose camera moved) is rendered over that room, scaled to
    the pass's size, where the avatar shows nothing; without one, over the avatar's own background."""
    import numpy as np
    from PIL import Image

    avatar, _ = load_avatar(DEMO)
    raster = Rasterizer(gl)
    cam = framing_camera(avatar.card.rest_vertices(), 20, 5, fov_y_deg=18.0, width_px=48, height_px=48)
    room = np.zeros((96, 96, 3), np.uint8)
    room[:, :48] = (200, 30, 160)  # left half magenta, right half green: the render's corners show which
    room[:, 48:] = (20, 180, 40)
    Image.fromarray(room).save(tmp_path / "room.png")
    results: queue.Queue = queue.Queue()
    corners = {}
    for name, path in (("room", str(tmp_path / "room.png")), ("none", None)):
        request = Request(avatar.card.at_rest(Controls()), cam, ("final",), room=path)
        render_passes(avatar, raster, request, 1, lambda rid: False, results, {})
        sent = [results.get_nowait() for _ in range(results.qsize())]
        rgb = next(m for m in sent if m[0] == "result")[3]["rgb"]
        corners[name] = np.round(255 * rgb[[0, 0, -1, -1], [0, -1, 0, -1]]).astype(int)
    np.testing.assert_allclose(corners["room"], [[200, 30, 160], [20, 180, 40], [200, 30, 160], [20, 180, 40]],
                               atol=2)
    assert not np.allclose(corners["none"], corners["room"], atol=20)
    raster.release()
